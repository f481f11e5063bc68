// Per-scene reference counts that order scene deletion against job creation without a lock over
// all scenes held during long work. CreateJob holds a reference while it loads the scene, counts
// its elements and inserts the job; DeleteScene deletes only a scene nobody references, and while
// it decides, new references to that scene wait. The mutex here guards the map only and is never
// held across loading, counting or database access.
#ifndef RADIOSITY_SERVER_SCENE_REFS_H_
#define RADIOSITY_SERVER_SCENE_REFS_H_

#include <condition_variable>
#include <cstdint>
#include <map>
#include <mutex>
#include <optional>
#include <string>

namespace radiosity::service {

class SceneRefs {
 public:
  // A reference to one scene, released when destroyed.
  class Ref {
   public:
    Ref(Ref&& other) noexcept : refs_(other.refs_), id_(std::move(other.id_)) {
      other.refs_ = nullptr;
    }
    Ref(const Ref&) = delete;
    Ref& operator=(const Ref&) = delete;
    Ref& operator=(Ref&&) = delete;
    ~Ref();

   private:
    friend class SceneRefs;
    Ref(SceneRefs* refs, std::string id) : refs_(refs), id_(std::move(id)) {}
    SceneRefs* refs_;
    std::string id_;
  };

  // The right to delete one scene, held while DeleteScene checks and deletes it (released when
  // destroyed). References wait for it.
  class Deletion {
   public:
    Deletion(Deletion&& other) noexcept : refs_(other.refs_), id_(std::move(other.id_)) {
      other.refs_ = nullptr;
    }
    Deletion(const Deletion&) = delete;
    Deletion& operator=(const Deletion&) = delete;
    Deletion& operator=(Deletion&&) = delete;
    ~Deletion();

   private:
    friend class SceneRefs;
    Deletion(SceneRefs* refs, std::string id) : refs_(refs), id_(std::move(id)) {}
    SceneRefs* refs_;
    std::string id_;
  };

  // References scene `id`, waiting while a deletion of it is deciding.
  Ref Acquire(const std::string& id);

  // Starts deleting scene `id` (after another deletion of it has finished). When the scene is
  // referenced, returns nothing and sets `*references` to the count.
  std::optional<Deletion> BeginDelete(const std::string& id, int64_t* references);

 private:
  struct Entry {
    int64_t refs = 0;
    bool deleting = false;
  };
  void Release(const std::string& id);
  void EndDelete(const std::string& id);
  void EraseIfUnusedLocked(std::map<std::string, Entry>::iterator it);

  std::mutex mu_;
  std::condition_variable cv_;
  std::map<std::string, Entry> scenes_;  // Only scenes referenced or being deleted.
};

}  // namespace radiosity::service

#endif  // RADIOSITY_SERVER_SCENE_REFS_H_
