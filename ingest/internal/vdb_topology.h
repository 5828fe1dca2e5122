// The compact topology of one float or double grid of a .vdb file, read by
// streaming through the file instead of building OpenVDB's tree. Private to
// ingest and its tests (includes OpenVDB).
//
// OpenVDB's own tree, even with delayed loading, keeps every leaf node (its
// masks, a buffer with a file-info block) and every internal node's full
// child table in memory: hundreds of bytes per leaf, which made a 2.8 GB
// level set need 2 GB. CompactTopology reads the same bytes (the grid's
// topology section, then the leaf buffers section once, skipping the values)
// and keeps per leaf only its origin, active-voxel count and file offset
// (24 bytes); per internal node its child mask and its tile values, packed
// against the few distinct values a node usually holds. Leaf values are
// decoded on demand from the file with OpenVDB's own decoder
// (io::readCompressedValues), so they are bit for bit OpenVDB's.
//
// Layout assumptions, checked while reading: a Tree4<T, 5, 4, 3> (FloatGrid
// or DoubleGrid) in file format 222 or later (OpenVDB 3.0+), not an instance.
//
// Thread safety: after Read() the object is immutable; Lookup and
// ReadLeaf may be called from many threads (each with its own scratch).
#ifndef VOX_INGEST_INTERNAL_VDB_TOPOLOGY_H_
#define VOX_INGEST_INTERNAL_VDB_TOPOLOGY_H_

#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include <openvdb/openvdb.h>

#include "core/util/status.h"
#include "ingest/internal/vdb_layout.h"

namespace vox::ingest_internal {

template <class ValueT>
class CompactTopology {
 public:
  using Mask = openvdb::util::NodeMask<3>;  // a leaf's 8^3 value mask

  struct Leaf {
    int32_t origin[3];
    uint32_t active;  // active voxels
    uint64_t pos;     // file offset of its buffer record (value mask, then values)
    openvdb::Coord Origin() const { return openvdb::Coord(origin[0], origin[1], origin[2]); }
  };
  // An active tile (any level), as a box of voxels.
  struct Tile {
    openvdb::CoordBBox box;
    ValueT value;
  };
  // What lies at a voxel: a leaf (index into leaves()) or a value.
  struct Where {
    int64_t leaf = -1;
    ValueT value{};
  };

  // Reads grid `grid` of the file at `path` (whose layout ReadVdbLayout gave).
  static StatusOr<std::unique_ptr<CompactTopology>> Read(const std::string& path,
                                                         const VdbLayout& layout,
                                                         const VdbLayout::Grid& grid);
  ~CompactTopology();

  const std::vector<Leaf>& leaves() const { return leaves_; }
  const std::vector<Tile>& active_tiles() const { return tiles_; }
  ValueT background() const { return background_; }
  uint64_t active_voxels() const { return active_voxels_; }
  // Bytes held (tables), for the memory budget.
  uint64_t MemoryBytes() const;

  Where Lookup(const openvdb::Coord& c) const;

  // Decodes leaf i's values (offset x << 6 | y << 3 | z) and value mask.
  // Throws openvdb::Exception for corrupt data (as OpenVDB's reader does).
  void ReadLeaf(size_t i, ValueT values[512], Mask* mask, std::vector<char>* scratch) const;

 private:
  struct Node;  // an internal node (either level)
  class Parser;
  CompactTopology() = default;

  int fd_ = -1;
  std::string path_;
  uint32_t file_version_ = 0, lib_major_ = 0, lib_minor_ = 0, compression_ = 0;
  bool half_ = false;
  ValueT background_{};
  std::vector<Leaf> leaves_;
  uint64_t leaves_end_ = 0;  // end of the last leaf's record
  std::vector<Tile> tiles_;
  uint64_t active_voxels_ = 0;
  // Root: key of a 4096^3 block -> index of its node (>= 0) or ~index of a root tile.
  std::unordered_map<uint64_t, int64_t> root_;
  std::vector<ValueT> root_tiles_;
  std::vector<Node> upper_;  // level 2 (32^3 children of 128^3 voxels)
  std::vector<Node> lower_;  // level 1 (16^3 children: leaves)
};

}  // namespace vox::ingest_internal

#endif  // VOX_INGEST_INTERNAL_VDB_TOPOLOGY_H_
