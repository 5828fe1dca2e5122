// Bricks and blocks of one density: the inside of a fog. A full brick whose
// voxels all hold one value decodes to that value and a cell pool shared by
// every such brick (FullPool); in other bricks, aligned blocks of 2^k voxels
// of one density are found once at decode, so that rays cross each block as
// one cell (Volume::PinnedDensity).
#ifndef VOX_STORAGE_INTERNAL_BRICK_UNIFORM_H_
#define VOX_STORAGE_INTERNAL_BRICK_UNIFORM_H_

#include <cstddef>
#include <cstdint>
#include <memory>

#include "storage/internal/brick_codec.h"

namespace vox::storage_internal {

// Whether the n bytes at p all equal `byte`.
bool AllBytesAre(const uint8_t* p, size_t n, uint8_t byte);

// A brick record of `depth` levels with every voxel occupied, all with
// voxel 0's attributes, as a full_of_one DecodedBrick; null when it is not
// one. `masks` and `planes` are the record's (DeltaPlanes form: each plane
// holds voxel 0's byte, then the differences, which are all zero).
std::shared_ptr<DecodedBrick> DecodeFullOfOne(const uint8_t* masks, uint32_t num_cells,
                                              const uint8_t* planes, uint32_t voxel_count,
                                              int depth, uint8_t flags);

// A full_of_one DecodedBrick of `depth` levels whose voxels all hold the
// attributes at `voxel` (one voxel's value arrays: AttrBytesPerVoxel(flags)
// bytes).
std::shared_ptr<DecodedBrick> FullOfOneBrick(const uint8_t* voxel, uint32_t voxel_count, int depth,
                                             uint8_t flags);

// Sets b's uniform_density, or its uniform_levels: bottom-up, each full
// cell's one density; top-down, each cell's largest block of one density
// around it. `level_start[l]`: the first cell of level l (level order),
// level_start[depth] the cell count. `values`: b's value arrays (decoded
// planes, not deltas), b->voxel_count voxels.
void FindUniformBlocks(DecodedBrick* b, int depth, const uint32_t* level_start, const uint8_t* values);

// Sets the attributes of b, whose one attribute is density, from `values`
// (b->voxel_count densities): where at least half the voxels share the
// density of a block FindUniformBlocks found, in the common form
// (DecodedBrick::common) when that takes less memory; else a copy in
// attr_values.
void KeepAttributes(DecodedBrick* b, const uint8_t* values);

}  // namespace vox::storage_internal

#endif  // VOX_STORAGE_INTERNAL_BRICK_UNIFORM_H_
