#include "render/store_volume.h"

namespace vox {

StatusOr<std::unique_ptr<StoreVolume>> StoreVolume::Open(const std::string& dir,
                                                         const OpenOptions& options) {
  VOX_ASSIGN_OR_RETURN(std::unique_ptr<Store> store, Store::Open(dir, options));
  return std::make_unique<StoreVolume>(std::move(store), dir);
}

}  // namespace vox
