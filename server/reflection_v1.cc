#include "server/reflection_v1.h"

#include <set>
#include <utility>

#include "absl/strings/str_cat.h"
#include "google/protobuf/descriptor.h"
#include "google/protobuf/descriptor.pb.h"

namespace radiosity::service {
namespace {

namespace pb = google::protobuf;
using grpc::reflection::v1::ServerReflectionRequest;
using grpc::reflection::v1::ServerReflectionResponse;

// One stream: each request answered in order, one write in flight. Every answer is a lookup in
// the generated pool (no I/O, no locks held long), so it is made on the reactor's thread.
class Reactor : public grpc::ServerBidiReactor<ServerReflectionRequest, ServerReflectionResponse> {
 public:
  explicit Reactor(const std::vector<std::string>* services) : services_(services) {
    StartRead(&request_);
  }

  void OnReadDone(bool ok) override {
    if (!ok) {
      Finish(grpc::Status::OK);  // The client has sent all it will.
      return;
    }
    response_.Clear();
    Answer();
    StartWrite(&response_);
  }

  void OnWriteDone(bool ok) override {
    if (!ok) {
      Finish(grpc::Status(grpc::StatusCode::UNKNOWN, "the reflection response was not sent"));
      return;
    }
    StartRead(&request_);
  }

  void OnDone() override { delete this; }

 private:
  void Answer() {
    response_.set_valid_host(request_.host());
    *response_.mutable_original_request() = request_;
    const pb::DescriptorPool* pool = pb::DescriptorPool::generated_pool();
    switch (request_.message_request_case()) {
      case ServerReflectionRequest::kListServices:
        for (const std::string& name : *services_) {
          response_.mutable_list_services_response()->add_service()->set_name(name);
        }
        return;
      case ServerReflectionRequest::kFileByFilename:
        return SendFile(pool->FindFileByName(request_.file_by_filename()),
                        request_.file_by_filename());
      case ServerReflectionRequest::kFileContainingSymbol:
        return SendFile(pool->FindFileContainingSymbol(request_.file_containing_symbol()),
                        request_.file_containing_symbol());
      case ServerReflectionRequest::kFileContainingExtension: {
        const auto& ext = request_.file_containing_extension();
        const pb::Descriptor* type = pool->FindMessageTypeByName(ext.containing_type());
        const pb::FieldDescriptor* field =
            type ? pool->FindExtensionByNumber(type, ext.extension_number()) : nullptr;
        return SendFile(field ? field->file() : nullptr,
                        absl::StrCat(ext.containing_type(), " extension ", ext.extension_number()));
      }
      case ServerReflectionRequest::kAllExtensionNumbersOfType: {
        const pb::Descriptor* type =
            pool->FindMessageTypeByName(request_.all_extension_numbers_of_type());
        if (type == nullptr) return Error(request_.all_extension_numbers_of_type());
        std::vector<const pb::FieldDescriptor*> extensions;
        pool->FindAllExtensions(type, &extensions);
        auto* out = response_.mutable_all_extension_numbers_response();
        out->set_base_type_name(type->full_name());
        for (const pb::FieldDescriptor* f : extensions) out->add_extension_number(f->number());
        return;
      }
      case ServerReflectionRequest::MESSAGE_REQUEST_NOT_SET:
        break;
    }
    response_.mutable_error_response()->set_error_code(
        static_cast<int>(grpc::StatusCode::UNIMPLEMENTED));
    response_.mutable_error_response()->set_error_message("no request was set");
  }

  void Error(const std::string& what) {
    response_.mutable_error_response()->set_error_code(
        static_cast<int>(grpc::StatusCode::NOT_FOUND));
    response_.mutable_error_response()->set_error_message(absl::StrCat(what, " not found"));
  }

  // `file` (always) and, depth first, the files it imports that this stream has not had.
  void SendFile(const pb::FileDescriptor* file, const std::string& what) {
    if (file == nullptr) return Error(what);
    auto* out = response_.mutable_file_descriptor_response();
    std::vector<const pb::FileDescriptor*> stack = {file};
    while (!stack.empty()) {
      const pb::FileDescriptor* f = stack.back();
      stack.pop_back();
      if (!sent_.insert(f->name()).second && f != file) continue;
      pb::FileDescriptorProto proto;
      f->CopyTo(&proto);
      out->add_file_descriptor_proto(proto.SerializeAsString());
      for (int i = 0; i < f->dependency_count(); ++i) stack.push_back(f->dependency(i));
    }
  }

  const std::vector<std::string>* services_;
  ServerReflectionRequest request_;
  ServerReflectionResponse response_;
  std::set<std::string> sent_;
};

}  // namespace

ReflectionV1Service::ReflectionV1Service(std::vector<std::string> services)
    : services_(std::move(services)) {}

grpc::ServerBidiReactor<ServerReflectionRequest, ServerReflectionResponse>*
ReflectionV1Service::ServerReflectionInfo(grpc::CallbackServerContext* /*context*/) {
  return new Reactor(&services_);
}

}  // namespace radiosity::service
