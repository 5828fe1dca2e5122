// Leaf values read without touching the tree: the private leaf-value reader
// of the ingest. Private to ingest and its tests (includes OpenVDB).
//
// With delayed loading, reading a value through the tree loads the leaf's
// buffer into the tree for good. Instead, every leaf is decoded into a
// private copy of its (out-of-core) buffer, used, and dropped, so the tree
// stays topology-only and memory stays bounded. It also sidesteps an
// OpenVDB 10 defect: when LeafBuffer::doLoad throws (corrupt leaf data) it
// leaves the buffer claiming to be out of core while holding an array, and
// destroying or reading that buffer again crashes. A private copy that fails
// to decode is deliberately leaked (a few kB, corrupt files only) and the
// tree's own buffers are never loaded.
//
// Thread safety: one LeafValues / PrivateReader per thread; many of them may
// read the same (const) tree at once.
#ifndef VOX_INGEST_INTERNAL_LEAF_VALUES_H_
#define VOX_INGEST_INTERNAL_LEAF_VALUES_H_

#include <memory>
#include <unordered_map>
#include <vector>

#include <openvdb/openvdb.h>

namespace vox::ingest_internal {

template <class LeafT>
class LeafValues {
 public:
  using Buffer = typename LeafT::Buffer;
  using ValueT = typename LeafT::ValueType;

  // The leaf's values (offset x << 6 | y << 3 | z), decoded once per
  // LeafValues; may throw an OpenVDB exception for corrupt data.
  const ValueT* Get(const LeafT* leaf) {
    if (leaf == last_leaf_) return last_data_;
    auto it = index_.find(leaf);
    const ValueT* data;
    if (it != index_.end()) {
      data = it->second;
    } else {
      const Buffer& in_tree = leaf->buffer();
      if (!in_tree.isOutOfCore() && !in_tree.empty()) {
        data = in_tree.data();  // already in memory (delayed loading off)
      } else {
        auto* copy = new Buffer(in_tree);  // shares the file mapping, reads nothing yet
        data = copy->data();  // decodes; if this throws, `copy` is leaked on purpose
        owned_.emplace_back(copy);
      }
      index_.emplace(leaf, data);
    }
    last_leaf_ = leaf;
    last_data_ = data;
    return data;
  }
  void Clear() {
    index_.clear();
    owned_.clear();
    last_leaf_ = nullptr;
  }

 private:
  std::unordered_map<const LeafT*, const ValueT*> index_;
  std::vector<std::unique_ptr<Buffer>> owned_;
  const LeafT* last_leaf_ = nullptr;
  const ValueT* last_data_ = nullptr;
};

// A tree accessor that caches the internal nodes but never a leaf: OpenVDB's
// default accessor keeps a pointer to the cached leaf's values, which loads
// the leaf's buffer into the tree.
template <class TreeT>
using NoLeafAccessor = openvdb::tree::ValueAccessor2<const TreeT, false, 1, 2>;

// Values of a whole tree read through LeafValues: leaves decoded privately,
// tiles and background from the topology.
template <class GridT>
class PrivateReader {
 public:
  using TreeT = typename GridT::TreeType;
  using LeafT = typename TreeT::LeafNodeType;
  using ValueT = typename GridT::ValueType;

  explicit PrivateReader(const GridT& grid) : acc_(grid.constTree()) {}

  ValueT Value(const openvdb::Coord& c) {
    if (const LeafT* leaf = acc_.probeConstLeaf(c))
      return leaves_.Get(leaf)[LeafT::coordToOffset(c)];
    return acc_.getValue(c);  // a tile or the background: no leaf buffer involved
  }
  const ValueT* Leaf(const LeafT* leaf) { return leaves_.Get(leaf); }
  void Clear() { leaves_.Clear(); }

 private:
  NoLeafAccessor<TreeT> acc_;
  LeafValues<LeafT> leaves_;
};

}  // namespace vox::ingest_internal

#endif  // VOX_INGEST_INTERNAL_LEAF_VALUES_H_
