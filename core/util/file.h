// The file layer under vox's store: read-only random access files (read
// with pread, memory mapped, in memory, and a fault-injecting wrapper for
// tests), an append-only writable file, temporaries and their atomic
// publication, and the process's disk read counter. Every error names the
// file.
//
// Thread safety: RandomAccessFile::Read and CurrentSize are thread-safe.
// A WritableFile is used by one thread at a time. FaultInjectionFile's
// setters must not race with reads.
#ifndef VOX_CORE_UTIL_FILE_H_
#define VOX_CORE_UTIL_FILE_H_

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <string>

#include "core/util/status.h"

namespace vox {

class RandomAccessFile {
 public:
  virtual ~RandomAccessFile() = default;
  virtual const std::string& path() const = 0;
  // Size when opened (what a mapping covers).
  virtual uint64_t size() const = 0;
  // Copies bytes [offset, offset + n) into scratch. A range past size() is
  // Corruption (the caller trusted an index); a file that shrank underneath
  // is IoError. Both name the file.
  virtual Status Read(uint64_t offset, size_t n, uint8_t* scratch) const = 0;
  // The size on disk now (fstat), to notice a file that shrank while open.
  virtual StatusOr<uint64_t> CurrentSize() const { return size(); }
};

// Opens `path` for reads with pread(2): a read costs the pages it covers and
// nothing more (no page-fault read-around, which on a disk with a large
// read_ahead_kb turns each small brick read into megabytes). A file that
// shrank underneath gives IoError naming the file (a short read is checked
// against fstat). `random_access` also tells the kernel not to read ahead
// (posix_fadvise RANDOM); by default its heuristics still read ahead for
// sequential runs of reads.
StatusOr<std::unique_ptr<RandomAccessFile>> OpenPreadFile(const std::string& path,
                                                          bool random_access = false);

// Maps `path` read-only. Reads copy out of the mapping under a SIGBUS guard:
// a file truncated under a running process gives IoError naming the file,
// never an unexplained SIGBUS. `check_size_each_read` also fstat()s before
// each read, for a precise message (tests turn it off to reach the guard).
// `random_access` sets madvise(MADV_RANDOM) on the mapping (faults read
// single pages instead of reading around).
StatusOr<std::unique_ptr<RandomAccessFile>> OpenMmapFile(const std::string& path,
                                                         bool check_size_each_read = true,
                                                         bool random_access = false);

// A file held in memory, named `name` in messages.
std::unique_ptr<RandomAccessFile> NewMemoryFile(std::string name, std::string contents);

// Wraps a file and injects faults: failing reads (IoError) after a number
// of successful ones, or bit flips at one byte offset. For tests.
class FaultInjectionFile : public RandomAccessFile {
 public:
  explicit FaultInjectionFile(std::unique_ptr<RandomAccessFile> base) : base_(std::move(base)) {}
  const std::string& path() const override { return base_->path(); }
  uint64_t size() const override { return base_->size(); }
  Status Read(uint64_t offset, size_t n, uint8_t* scratch) const override;
  StatusOr<uint64_t> CurrentSize() const override { return base_->CurrentSize(); }

  // Reads after the next `n` successful ones fail; -1 never fails.
  void FailReadsAfter(int64_t n) { fail_after_ = n; }
  // Every `n`th read fails (IoError), the others succeed; 0 turns it off.
  void FailEveryNthRead(uint64_t n) { fail_every_ = n; }
  uint64_t injected_failures() const { return injected_.load(); }
  // Reads covering byte `offset` see it XORed with `mask`.
  void FlipByte(uint64_t offset, uint8_t mask) {
    flip_offset_ = offset;
    flip_mask_ = mask;
  }
  uint64_t reads() const { return reads_.load(); }

 private:
  std::unique_ptr<RandomAccessFile> base_;
  mutable std::atomic<int64_t> fail_after_{-1};
  uint64_t flip_offset_ = UINT64_MAX;
  uint8_t flip_mask_ = 0;
  mutable std::atomic<uint64_t> reads_{0};
  std::atomic<uint64_t> fail_every_{0};
  mutable std::atomic<uint64_t> calls_{0}, injected_{0};
};

// An append-only file written through a buffer. Errors (disk full, file too
// large, permission) name the file and the OS error.
class WritableFile {
 public:
  // Creates `path`, failing if it exists.
  static StatusOr<std::unique_ptr<WritableFile>> Create(const std::string& path);
  // Opens the existing `path` to append after its first `keep` bytes (the
  // rest is cut off).
  static StatusOr<std::unique_ptr<WritableFile>> OpenAppend(const std::string& path, uint64_t keep);
  ~WritableFile();
  WritableFile(const WritableFile&) = delete;
  WritableFile& operator=(const WritableFile&) = delete;

  Status Append(const void* data, size_t n);
  Status Append(const std::string& s) { return Append(s.data(), s.size()); }
  // Flushes the buffer and fsyncs.
  Status Sync();
  Status Close();
  uint64_t size() const { return size_; }
  const std::string& path() const { return path_; }
  // Hands the buffer to the OS (no fsync): it survives the process.
  Status Flush();

 private:
  WritableFile(std::string path, int fd) : path_(std::move(path)), fd_(fd) {}
  std::string path_;
  int fd_ = -1;
  std::string buf_;
  uint64_t size_ = 0;
};

// fsyncs a directory, so that renames and creations in it are durable.
Status SyncDir(const std::string& dir);

// Bytes this process has caused to be read from storage (the read_bytes
// line of /proc/self/io: page-cache misses, whatever read them; reads served
// from the page cache are not counted). Unavailable (Unsupported) where the
// kernel has no per-task I/O accounting.
StatusOr<uint64_t> ProcessIoBytes();

// Whether process `pid` is gone: there is no such process, or it is a
// zombie (exited, not reaped: its parent gone and a container's init that
// does not reap), which holds no files and writes no more. For removing the
// temporaries of killed writers.
bool ProcessGone(long pid);

// The directory and the name of `path`: "." and `path` for a bare name, "/"
// for a name in the root.
void SplitPath(const std::string& path, std::string* dir, std::string* name);

// The most bytes a camera or scene file may hold (16 MiB; a camera is a few
// hundred bytes): a larger one is refused before it is read.
inline constexpr uint64_t kMaxTextFileBytes = uint64_t(16) << 20;

// The bytes of a whole (small) text file, such as cam.json; NotFound and
// IoError name the file; InvalidArgument when it holds more than
// `max_bytes` (a regular file's size is checked before reading).
StatusOr<std::string> ReadTextFile(const std::string& path,
                                   uint64_t max_bytes = kMaxTextFileBytes);

// Temporaries and atomic publication. An output DIR/NAME (a file or a store
// directory) is built as a temporary beside it, synced, and published by a
// rename, so a reader sees the old output or the whole new one, never a
// part. The temporaries' names:
//   .NAME.tmp-PID-XXXXXX     a file (mkstemp's six letters and digits)
//   .NAME.tmp-PID-hhhhhhhh   a directory (eight lowercase hex digits), and
//                            with ".old" the replaced one on its way out
// A process killed outright cannot remove its temporaries: the next writer
// of the same NAME removes those of processes that are gone.

// Removes the temporaries of `name` in `dir` whose process is gone: entries
// of exactly the patterns above, the files' of regular files, the
// directories' of directories (not links). A live process's (another run
// writing the same output), this process's and anything else stay.
void RemoveStaleTemporaries(const std::string& dir, const std::string& name);

// Held while CreateTemporary makes a temporary and while an OutputGroup
// publishes (core/util/atomic_file.h). A tool's signal thread takes it for
// good before removing the process's temporaries, so that none is created,
// and no group half-published, after that.
std::mutex& TemporaryMutex();

// Creates an empty temporary file (`directory` false, mode 0644 less the
// umask) or directory beside `target`, named as above, after removing the
// stale temporaries of `target`. Returns its path. Writers open the file
// without O_CREAT, so a temporary removed under them is not made again.
StatusOr<std::string> CreateTemporary(const std::string& target, bool directory);

// What a writer found at its output path when it checked it, before the
// long work: nothing, or the file or directory of this device and inode.
// PublishAtomically replaces only that.
struct CheckedTarget {
  bool exists = false;
  bool directory = false;  // a directory (lstat: a link is not one)
  uint64_t device = 0, inode = 0;
};

// What is at `target` now (lstat). IoError naming it when it cannot be
// examined (anything but "no such file").
StatusOr<CheckedTarget> CheckTarget(const std::string& target);

// Given where the replaced output now lies (moved out of the target, under
// a temporary name), "" when it may be removed, or why not.
using ReplaceCheck = std::function<std::string(const std::string& old_path)>;

// Puts the finished temporary `temp` (a synced file or directory, beside
// `target`) in place of `target` and fsyncs their directory. It never
// removes anything it did not check:
//  - `checked` found nothing: nothing is replaced (renameat2
//    RENAME_NOREPLACE; where the file system lacks it, link(2) for a file,
//    a placeholder directory for a directory). Anything at `target` now gives
//    InvalidArgument "'<target>' already exists".
//  - `checked` found something: it is exchanged with `temp` (RENAME_EXCHANGE;
//    else moved aside to `temp`.old first), and removed only when it is the
//    same device and inode, the same kind, and `may_replace` (if given)
//    accepts it. Otherwise it is put back as it was and the publish fails
//    with InvalidArgument "'<target>' changed after it was checked".
// `what` names the output in messages ("store", "output").
Status PublishAtomically(const std::string& temp, const std::string& target,
                         const std::string& what, const CheckedTarget& checked,
                         const ReplaceCheck& may_replace = nullptr);

// For tests: PublishAtomically behaves as on a file system without
// renameat2's flags (the fallbacks above).
void SetRenameFlagsUnsupportedForTesting(bool unsupported);

// "<what> '<path>': <strerror(err)>" as an IoError (ResourceExhausted for
// ENOSPC/EDQUOT/EFBIG, NotFound for ENOENT).
Status ErrnoError(const std::string& what, const std::string& path, int err);

}  // namespace vox

#endif  // VOX_CORE_UTIL_FILE_H_
