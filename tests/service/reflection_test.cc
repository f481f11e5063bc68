// Server reflection v1 (server/reflection_v1.h) against a real server on 127.0.0.1: the services
// listed, descriptors complete enough to rebuild the API (every import sent once per stream),
// NOT_FOUND for unknown symbols, and a stream that ends cleanly.
#include <gtest/gtest.h>

#include <algorithm>
#include <string>
#include <vector>

#include "google/protobuf/descriptor.h"
#include "google/protobuf/descriptor.pb.h"
#include "grpc/reflection/v1/reflection.grpc.pb.h"
#include "tests/service/fixture.h"

namespace radiosity {
namespace {

namespace pb = google::protobuf;
namespace refl = grpc::reflection::v1;

class ReflectionV1Test : public service::testing::ServiceTest {
 protected:
  void SetUp() override {
    service::ServerOptions options = service::testing::TestServerOptions(data_.path());
    options.reflection = true;
    ASSERT_NO_FATAL_FAILURE(Start(options));
  }
};

TEST_F(ReflectionV1Test, ListsServicesAndSendsDescriptorsThatRebuildTheApi) {
  auto stub = refl::ServerReflection::NewStub(client::MakeChannel(address()));
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
  auto stream = stub->ServerReflectionInfo(&context);
  auto ask = [&](const refl::ServerReflectionRequest& request) {
    refl::ServerReflectionResponse response;
    EXPECT_TRUE(stream->Write(request));
    EXPECT_TRUE(stream->Read(&response));
    EXPECT_EQ(response.original_request().SerializeAsString(), request.SerializeAsString());
    return response;
  };

  refl::ServerReflectionRequest list;
  list.set_list_services("");
  const refl::ServerReflectionResponse listed = ask(list);
  std::vector<std::string> names;
  for (const auto& s : listed.list_services_response().service()) names.push_back(s.name());
  for (const char* want :
       {"radiosity.v1.RadiosityService", "grpc.health.v1.Health",
        "grpc.reflection.v1.ServerReflection", "grpc.reflection.v1alpha.ServerReflection"}) {
    EXPECT_NE(std::find(names.begin(), names.end(), want), names.end()) << want;
  }

  refl::ServerReflectionRequest symbol;
  symbol.set_file_containing_symbol("radiosity.v1.RadiosityService");
  const refl::ServerReflectionResponse files = ask(symbol);
  ASSERT_TRUE(files.has_file_descriptor_response()) << files.DebugString();
  // Rebuild a pool from what was sent alone: imports first, as a client would.
  std::vector<pb::FileDescriptorProto> protos;
  for (const std::string& bytes : files.file_descriptor_response().file_descriptor_proto()) {
    ASSERT_TRUE(protos.emplace_back().ParseFromString(bytes));
  }
  EXPECT_EQ(protos.front().name(), "radiosity/v1/service.proto");
  pb::DescriptorPool pool;
  for (size_t built = 0, round = 0; built < protos.size() && round < protos.size(); ++round) {
    for (const pb::FileDescriptorProto& p : protos) {
      if (pool.FindFileByName(p.name()) != nullptr) continue;
      bool ready = true;
      for (const std::string& d : p.dependency()) ready = ready && pool.FindFileByName(d);
      if (ready && pool.BuildFile(p) != nullptr) ++built;
    }
  }
  const pb::ServiceDescriptor* service = pool.FindServiceByName("radiosity.v1.RadiosityService");
  ASSERT_NE(service, nullptr) << "the files sent do not rebuild the service";
  const pb::MethodDescriptor* watch = service->FindMethodByName("WatchJob");
  ASSERT_NE(watch, nullptr);
  EXPECT_TRUE(watch->server_streaming());
  const pb::Descriptor* spec = pool.FindMessageTypeByName("radiosity.v1.SolveSpec");
  ASSERT_NE(spec, nullptr);
  EXPECT_NE(spec->FindFieldByName("solve_method"), nullptr);
  // An import, sent along.
  EXPECT_NE(pool.FindFileByName("google/protobuf/timestamp.proto"), nullptr);

  // Asked again, the file comes alone: its imports were sent on this stream.
  refl::ServerReflectionRequest by_name;
  by_name.set_file_by_filename("radiosity/v1/service.proto");
  const refl::ServerReflectionResponse again = ask(by_name);
  EXPECT_EQ(again.file_descriptor_response().file_descriptor_proto_size(), 1);

  refl::ServerReflectionRequest unknown;
  unknown.set_file_containing_symbol("radiosity.v1.NoSuchThing");
  const refl::ServerReflectionResponse missing = ask(unknown);
  EXPECT_EQ(missing.error_response().error_code(), static_cast<int>(grpc::StatusCode::NOT_FOUND));
  EXPECT_NE(missing.error_response().error_message().find("radiosity.v1.NoSuchThing"),
            std::string::npos);

  refl::ServerReflectionRequest extensions;
  extensions.set_all_extension_numbers_of_type("radiosity.v1.SolveSpec");
  const refl::ServerReflectionResponse numbers = ask(extensions);
  EXPECT_EQ(numbers.all_extension_numbers_response().base_type_name(), "radiosity.v1.SolveSpec");
  EXPECT_EQ(numbers.all_extension_numbers_response().extension_number_size(), 0);

  stream->WritesDone();
  EXPECT_TRUE(stream->Finish().ok());
}

}  // namespace
}  // namespace radiosity
