// The journal of a resumable store write (WriteOptions::resume_key): a file
// `journal` beside bricks.vxb in the store's resumable directory, holding a
// header (magic, the store id, the key naming what is written) and one
// record per brick appended to bricks.vxb (its table entry and its voxels'
// bounds), each with its CRC32C. A record is written after its brick's
// bytes have reached the file, so after a kill (SIGKILL included) the
// records that read back whole and whose brick's bytes match their CRC are
// bricks the next run keeps; reading stops at the first that does not.
// Private to storage.
//
// Thread safety: a BrickJournal is used under its writer's lock.
#ifndef VOX_STORAGE_INTERNAL_BRICK_JOURNAL_H_
#define VOX_STORAGE_INTERNAL_BRICK_JOURNAL_H_

#include <cstdint>
#include <glm/vec3.hpp>
#include <memory>
#include <string>
#include <vector>

#include "core/util/status.h"
#include "storage/internal/format.h"
#include "storage/meta.h"

namespace vox::storage_internal {

struct JournalRecord {
  BrickEntry entry;           // where the brick's record lies in bricks.vxb, its sizes and CRC
  glm::u64vec3 lo{0}, hi{0};  // its voxels' bounds in the brick
};

// What an existing journal holds.
struct JournalContents {
  std::string key;
  uint64_t store_id = 0;
  std::vector<JournalRecord> records;  // verified against bricks.vxb, in file order
  uint64_t bricks_end = 0;             // bricks.vxb's bytes up to the last verified record
};

// The key a journal carries: what a resumed run must share with the earlier
// one (the caller's key, the store's metadata but its counts, the brick
// encoding).
std::string JournalKey(const std::string& caller_key, const StoreMeta& meta, int zstd_level,
                       int normal_bits);

class BrickJournal {
 public:
  ~BrickJournal();
  // Creates `path` (failing if it exists) with its header.
  static StatusOr<std::unique_ptr<BrickJournal>> Create(const std::string& path,
                                                        const std::string& key, uint64_t store_id);
  // Reads the journal at `path` and verifies its records against the brick
  // file `bricks_path` (header included). Corruption when the header is not
  // a journal's; records past the first bad one are not returned.
  static StatusOr<JournalContents> Read(const std::string& path, const std::string& bricks_path);
  // Opens `path` to append after its first `keep_bytes` (the header and the
  // verified records: JournalBytes(n)).
  static StatusOr<std::unique_ptr<BrickJournal>> Reopen(const std::string& path,
                                                        uint64_t keep_bytes);
  static uint64_t JournalBytes(const std::string& key, size_t records);

  // Appends one record (written to the file at once; not synced).
  Status Append(const JournalRecord& r);

 private:
  BrickJournal(std::string path, int fd) : path_(std::move(path)), fd_(fd) {}
  std::string path_;
  int fd_ = -1;
};

}  // namespace vox::storage_internal

#endif  // VOX_STORAGE_INTERNAL_BRICK_JOURNAL_H_
