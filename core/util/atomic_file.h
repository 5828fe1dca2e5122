// Atomic output files for vox-render and vox-merge: every output (EXR, PNG
// preview, --stats JSON) is written to a temporary file in the target's
// directory (core/util/file.h's CreateTemporary: `.NAME.tmp-PID-XXXXXX`), then
// fsynced and published over the target (PublishAtomically). A failed or
// interrupted write removes the temporary and leaves any earlier file at the
// target untouched. A process killed outright (SIGKILL, a node lost) cannot
// remove its temporary: the next AtomicFile for the same target removes such
// temporaries whose process is gone.
//
// Thread safety: thread-compatible (one AtomicFile per output).
#ifndef VOX_CORE_UTIL_ATOMIC_FILE_H_
#define VOX_CORE_UTIL_ATOMIC_FILE_H_

#include <string>
#include <utility>
#include <vector>

#include "core/util/file.h"
#include "core/util/status.h"

namespace vox {

// OkStatus when `path` can be written atomically (an EXR, a PNG, a JSON):
// its directory exists, is a directory and is writable, and `path` itself is
// not a directory. Cheap; tools run it on every output path before any long
// work, so a bad output path fails first.
Status CheckOutputPath(const std::string& path);

// True when a and b name the same existing file (same device and inode).
bool SameFile(const std::string& a, const std::string& b);

class AtomicFile {
 public:
  // Creates the (empty) temporary file beside `path`, first removing stale
  // temporaries of `path` whose process no longer runs.
  static StatusOr<AtomicFile> Create(const std::string& path);
  AtomicFile(AtomicFile&& o) noexcept;
  AtomicFile& operator=(AtomicFile&& o) noexcept;
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;
  // Removes the temporary unless Commit succeeded.
  ~AtomicFile();

  const std::string& path() const { return path_; }
  // Where to write the content (closed: the writer opens it by name).
  const std::string& temp_path() const { return temp_; }
  // fsyncs the temporary (once; a failure removes it).
  Status Sync();
  // Sync, then renames the temporary over path() and fsyncs the directory.
  // It replaces only the file found at path() by Create (same device and
  // inode), or nothing if there was none: a directory, or anything else put
  // there since, is refused and left as it is (InvalidArgument).
  Status Commit();
  // Removes the temporary now.
  void Abandon();

 private:
  AtomicFile() = default;
  std::string path_, temp_;
  bool synced_ = false;
  CheckedTarget checked_;
};

// Writes `bytes` to `path` atomically.
Status WriteFileAtomically(const std::string& path, const std::string& bytes);

// The outputs of one run (an EXR, its preview, the --stats JSON), published
// as a group: each is finished in its temporary first, and Commit puts them
// in place only when all were written. A device or pipe (/dev/stdout) takes
// its bytes in place at Commit, before any rename, so a failed write there
// leaves every earlier output as it was. Destroyed uncommitted, it removes
// the temporaries.
class OutputGroup {
 public:
  // A finished temporary, to be renamed into place by Commit.
  void AddFile(AtomicFile file) { files_.push_back(std::move(file)); }
  // The temporary holding the added output for `path` (empty: none).
  std::string TempOf(const std::string& path) const {
    for (const AtomicFile& f : files_)
      if (f.path() == path) return f.temp_path();
    return "";
  }
  // `bytes` for `path`: written to its temporary now (a device or pipe: kept
  // for Commit).
  Status AddBytes(const std::string& path, std::string bytes);
  // Writes the devices' bytes, then fsyncs and renames every temporary.
  Status Commit();

 private:
  std::vector<AtomicFile> files_;
  std::vector<std::pair<std::string, std::string>> special_;  // path, bytes
};

}  // namespace vox

#endif  // VOX_CORE_UTIL_ATOMIC_FILE_H_
