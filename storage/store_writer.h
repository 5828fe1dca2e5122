// vox::StoreWriter: writes a store directory (storage/FORMAT.md) brick by
// brick, in a temporary directory beside the target that Finish() fsyncs and
// renames into place. BrickVoxel is one voxel handed to it; WriteOptions its
// settings.
//
// Thread safety: AddBrick may be called from several threads at once (bricks
// are encoded and compressed in parallel, appended in turn); Finish must not
// race with AddBrick.
#ifndef VOX_STORAGE_STORE_WRITER_H_
#define VOX_STORAGE_STORE_WRITER_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <glm/vec3.hpp>

#include "core/util/status.h"
#include "storage/meta.h"

namespace vox {

// One occupied voxel handed to the writer, in brick-local coordinates
// (each < 2^(levels - brick_level)).
struct BrickVoxel {
  uint32_t x = 0, y = 0, z = 0;
  VoxelAttributes attr;
};

struct WriteOptions {
  int zstd_level = 3;
  bool force = false;  // replace an existing store at the target
  // Precision of each octahedral normal component, 8..16 bits. Readers need
  // not know: values stay 16-bit, multiples of 2^(16 - bits). 12 bits (max
  // error 0.06 degrees; 16 bits: 0.004) makes level-set stores about a third smaller.
  int normal_bits = 16;
  // The id both files carry (FORMAT.md); 0: random. A fixed id (with bricks
  // added in a fixed order, one at a time) makes the store byte-reproducible.
  uint64_t store_id = 0;
  // Called by Finish with the temporary directory once the store in it is
  // complete and synced, before it is renamed into place: what it adds to
  // the directory (e.g. the level-of-detail pyramid, storage/lod.h) is
  // published with the store, and an error leaves no store at the target.
  std::function<Status(const std::string& temp_dir)> before_publish;
  // Resumable writing (vox-ingest --resume) when non-empty: the store is
  // built in `.NAME.resume` beside the target (not a temporary of this
  // process), with a journal of the bricks written
  // (storage/internal/brick_journal.h) that outlives an error, an interrupt
  // or a kill. A later writer of the same target with the same key and
  // metadata keeps the bricks the journal verifies against the brick file
  // (Resumed) and takes the others; with another key, or an unreadable
  // journal, it starts over. Only one writer at a time uses the directory
  // (a lock); it refuses a `.NAME.resume` that is not a directory or holds
  // files of its own without a journal. It is renamed into place by Finish,
  // which removes the journal just before; until then Store::Open refuses
  // the directory (it holds a journal). Stores whose bricks are single
  // voxels (levels == brick_level) are not journaled.
  std::string resume_key;
};

class StoreWriter {
 public:
  // Prepares a store at `dir`: builds in a temporary directory beside it,
  // which Finish() fsyncs and renames into place. Refuses an existing target
  // unless options.force. `meta` gives everything but the counts, which the
  // writer fills in.
  static StatusOr<std::unique_ptr<StoreWriter>> Create(const std::string& dir,
                                                       const StoreMeta& meta,
                                                       const WriteOptions& options);
  virtual ~StoreWriter() = default;  // without Finish(): removes the temporary directory
  // Adds the brick of the brick-level octant `brick_coord` (grid coordinates
  // >> (levels - brick_level)). Bricks come in any order, each octant once,
  // each with at least one voxel; voxels in any order, no duplicates.
  virtual Status AddBrick(const glm::u64vec3& brick_coord, std::vector<BrickVoxel> voxels) = 0;
  // Writes the top and the index, fsyncs and renames into place.
  virtual Status Finish() = 0;
  // The temporary directory the store is built in until Finish renames it
  // (what before_publish is given); empty for writers without one.
  virtual std::string temp_dir() const { return {}; }
  // Resumable writing: the bricks kept from an earlier run, and whether
  // `brick_coord` is one of them (with its voxel count in *voxels); such a
  // brick is not added again. `resume_note` says what happened to an
  // earlier run's directory (empty: there was none).
  virtual uint64_t resumed_bricks() const { return 0; }
  virtual bool Resumed(const glm::u64vec3& /*brick_coord*/, uint32_t* /*voxels*/) const {
    return false;
  }
  virtual std::string resume_note() const { return {}; }
};

// The directory a resumable write of the store `dir` uses: `.NAME.resume` beside it.
std::string ResumeDirectory(const std::string& dir);
// Its journal: while it is there, the directory holds bricks for the next
// run to continue from.
std::string ResumeJournal(const std::string& dir);

}  // namespace vox

#endif  // VOX_STORAGE_STORE_WRITER_H_
