#include "server/scene_refs.h"

namespace radiosity::service {

SceneRefs::Ref::~Ref() {
  if (refs_) refs_->Release(id_);
}

SceneRefs::Deletion::~Deletion() {
  if (refs_) refs_->EndDelete(id_);
}

SceneRefs::Ref SceneRefs::Acquire(const std::string& id) {
  std::unique_lock<std::mutex> lock(mu_);
  cv_.wait(lock, [&] {
    auto it = scenes_.find(id);
    return it == scenes_.end() || !it->second.deleting;
  });
  ++scenes_[id].refs;
  return Ref(this, id);
}

std::optional<SceneRefs::Deletion> SceneRefs::BeginDelete(const std::string& id,
                                                          int64_t* references) {
  std::unique_lock<std::mutex> lock(mu_);
  cv_.wait(lock, [&] {
    auto it = scenes_.find(id);
    return it == scenes_.end() || !it->second.deleting;
  });
  Entry& entry = scenes_[id];
  *references = entry.refs;
  if (entry.refs > 0) return std::nullopt;
  entry.deleting = true;
  return Deletion(this, id);
}

void SceneRefs::Release(const std::string& id) {
  std::lock_guard<std::mutex> lock(mu_);
  auto it = scenes_.find(id);
  if (it == scenes_.end()) return;
  --it->second.refs;
  EraseIfUnusedLocked(it);
}

void SceneRefs::EndDelete(const std::string& id) {
  {
    std::lock_guard<std::mutex> lock(mu_);
    auto it = scenes_.find(id);
    if (it == scenes_.end()) return;
    it->second.deleting = false;
    EraseIfUnusedLocked(it);
  }
  cv_.notify_all();
}

void SceneRefs::EraseIfUnusedLocked(std::map<std::string, Entry>::iterator it) {
  if (it->second.refs == 0 && !it->second.deleting) scenes_.erase(it);
}

}  // namespace radiosity::service
