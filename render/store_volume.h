// vox::StoreVolume: a RenderVolume over an open Store (storage/store.h).
//
// Thread safety: thread-safe, as the Store.
#ifndef VOX_RENDER_STORE_VOLUME_H_
#define VOX_RENDER_STORE_VOLUME_H_

#include <memory>
#include <string>

#include "render/volume.h"
#include "storage/store.h"

namespace vox {

class StoreVolume : public RenderVolume {
 public:
  static StatusOr<std::unique_ptr<StoreVolume>> Open(const std::string& dir,
                                                     const OpenOptions& options);
  explicit StoreVolume(std::unique_ptr<Store> store, std::string dir)
      : store_(std::move(store)), dir_(std::move(dir)) {}

  const StoreMeta& meta() const override { return store_->meta(); }
  OctreeView view() override { return store_->view(); }
  StatusOr<VoxelAttributes> Attributes(uint32_t brick, uint32_t payload) override {
    return store_->Attributes(brick, payload);
  }
  StatusOr<VoxelAttributes> HitAttributes(const Hit& hit) override {
    return store_->HitAttributes(hit);
  }
  CacheStats cache_stats() const override { return store_->cache_stats(); }
  std::string description() const override { return dir_; }
  Store* store() { return store_.get(); }

 private:
  std::unique_ptr<Store> store_;
  std::string dir_;
};

}  // namespace vox

#endif  // VOX_RENDER_STORE_VOLUME_H_
