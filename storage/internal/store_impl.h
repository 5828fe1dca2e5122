// Opening a store from already-open files, so tests can wrap them in
// FaultInjectionFile. Private to storage and its tests. Thread-safe.
#ifndef VOX_STORAGE_INTERNAL_STORE_IMPL_H_
#define VOX_STORAGE_INTERNAL_STORE_IMPL_H_

#include <memory>
#include <string>
#include <vector>

#include "core/util/file.h"
#include "storage/internal/format.h"
#include "storage/store.h"

namespace vox::storage_internal {

// Opens the store `dir` whose index and brick files are given. The index
// file is read at open (its brick table whole or by pages: OpenOptions::
// whole_table_bytes); the brick file is read on each cache miss.
StatusOr<std::unique_ptr<Store>> OpenStoreFromFiles(const std::string& dir,
                                                    std::unique_ptr<RandomAccessFile> index,
                                                    std::unique_ptr<RandomAccessFile> bricks,
                                                    const OpenOptions& options);

// The brick table of an open store, read whole and checked (the block's
// CRC, every row, the voxel sum): for vox-info and tests.
StatusOr<std::vector<BrickEntry>> BrickTable(const Store& store);

}  // namespace vox::storage_internal

#endif  // VOX_STORAGE_INTERNAL_STORE_IMPL_H_
