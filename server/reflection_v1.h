// gRPC server reflection v1 (grpc.reflection.v1.ServerReflection), beside the v1alpha service
// that Debian's gRPC 1.51 provides: clients such as grpcurl ask v1 first. Answers come from the
// process's generated descriptor pool, as v1alpha's do: the services listed are those the server
// registers, each file is sent with the files it imports that the stream has not had yet.
#ifndef RADIOSITY_SERVER_REFLECTION_V1_H_
#define RADIOSITY_SERVER_REFLECTION_V1_H_

#include <string>
#include <vector>

#include "grpc/reflection/v1/reflection.grpc.pb.h"

namespace radiosity::service {

class ReflectionV1Service : public grpc::reflection::v1::ServerReflection::CallbackService {
 public:
  // `services`: the full names list_services answers with.
  explicit ReflectionV1Service(std::vector<std::string> services);

  grpc::ServerBidiReactor<grpc::reflection::v1::ServerReflectionRequest,
                          grpc::reflection::v1::ServerReflectionResponse>*
  ServerReflectionInfo(grpc::CallbackServerContext* context) override;

 private:
  const std::vector<std::string> services_;
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_REFLECTION_V1_H_
