#include "core/util/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <mutex>
#include <optional>
#include <utility>

#include "core/util/file.h"

namespace vox {
namespace {

std::string ErrnoText() { return std::strerror(errno); }

Status SyncFd(int fd, const std::string& what) {
  if (fsync(fd) != 0) return IoError(what + ": fsync failed: " + ErrnoText());
  return OkStatus();
}

}  // namespace

Status CheckOutputPath(const std::string& path) {
  if (path.empty()) return InvalidArgumentError("empty output path");
  std::string dir, name;
  SplitPath(path, &dir, &name);
  if (name.empty() || name == "." || name == "..")
    return InvalidArgumentError(path + ": output path names a directory, not a file");
  struct stat st;
  if (stat(dir.c_str(), &st) != 0)
    return NotFoundError(path + ": output directory " + dir + " does not exist");
  if (!S_ISDIR(st.st_mode)) return InvalidArgumentError(path + ": " + dir + " is not a directory");
  if (access(dir.c_str(), W_OK | X_OK) != 0)
    return IoError(path + ": output directory " + dir + " is not writable");
  if (stat(path.c_str(), &st) == 0 && S_ISDIR(st.st_mode))
    return InvalidArgumentError(path + ": output path is a directory");
  return OkStatus();
}

bool SameFile(const std::string& a, const std::string& b) {
  struct stat sa, sb;
  if (stat(a.c_str(), &sa) != 0 || stat(b.c_str(), &sb) != 0) return false;
  return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
}

StatusOr<AtomicFile> AtomicFile::Create(const std::string& path) {
  VOX_RETURN_IF_ERROR(CheckOutputPath(path));
  struct stat st;
  if (stat(path.c_str(), &st) == 0 && !S_ISREG(st.st_mode))
    return InvalidArgumentError(path + ": not a regular file; this output is written to a " +
                                "temporary beside it and renamed over it");
  // What Commit may replace: the file found here now, or nothing.
  VOX_ASSIGN_OR_RETURN(const CheckedTarget checked, CheckTarget(path));
  StatusOr<std::string> temp = CreateTemporary(path, /*directory=*/false);
  if (!temp.ok()) return IoError(path + ": " + temp.status().message());
  AtomicFile f;
  f.path_ = path;
  f.temp_ = *temp;
  f.checked_ = checked;
  return f;
}

AtomicFile::AtomicFile(AtomicFile&& o) noexcept
    : path_(std::move(o.path_)),
      temp_(std::exchange(o.temp_, std::string())),
      synced_(o.synced_),
      checked_(o.checked_) {}

AtomicFile& AtomicFile::operator=(AtomicFile&& o) noexcept {
  if (this != &o) {
    Abandon();
    path_ = std::move(o.path_);
    temp_ = std::exchange(o.temp_, std::string());
    synced_ = o.synced_;
    checked_ = o.checked_;
  }
  return *this;
}

AtomicFile::~AtomicFile() { Abandon(); }

void AtomicFile::Abandon() {
  if (!temp_.empty()) unlink(temp_.c_str());
  temp_.clear();
}

Status AtomicFile::Sync() {
  if (temp_.empty()) return InternalError(path_ + ": output already committed or abandoned");
  if (synced_) return OkStatus();
  int fd = open(temp_.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    Status s = IoError(path_ + ": cannot reopen the temporary " + temp_ + ": " + ErrnoText());
    Abandon();
    return s;
  }
  Status s = SyncFd(fd, path_);
  close(fd);
  if (!s.ok()) {
    Abandon();
    return s;
  }
  synced_ = true;
  return OkStatus();
}

Status AtomicFile::Commit() {
  VOX_RETURN_IF_ERROR(Sync());
  Status s = PublishAtomically(temp_, path_, "output", checked_);
  if (!s.ok()) {
    s = IoError(path_ + ": cannot put the finished output into place: " + s.message());
    Abandon();
    return s;
  }
  temp_.clear();
  return OkStatus();
}

namespace {

bool IsSpecial(const std::string& path) {
  struct stat st;
  return stat(path.c_str(), &st) == 0 && (S_ISCHR(st.st_mode) || S_ISFIFO(st.st_mode));
}

// Writes `bytes` to the file at `path` (a temporary, or a device or pipe
// named `target`).
Status WriteBytes(const std::string& path, const std::string& target, const std::string& bytes) {
  int fd = open(path.c_str(), O_WRONLY | O_TRUNC | O_CLOEXEC);
  if (fd < 0) return IoError(target + ": cannot open for writing: " + ErrnoText());
  size_t done = 0;
  while (done < bytes.size()) {
    ssize_t n = write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      Status s = IoError(target + ": write failed: " + ErrnoText());
      close(fd);
      return s;
    }
    done += size_t(n);
  }
  if (close(fd) != 0) return IoError(target + ": write failed: " + ErrnoText());
  return OkStatus();
}

}  // namespace

Status WriteFileAtomically(const std::string& path, const std::string& bytes) {
  OutputGroup group;
  VOX_RETURN_IF_ERROR(group.AddBytes(path, bytes));
  return group.Commit();
}

Status OutputGroup::AddBytes(const std::string& path, std::string bytes) {
  if (IsSpecial(path)) {  // a device or pipe (/dev/stdout) is written in place
    special_.push_back({path, std::move(bytes)});
    return OkStatus();
  }
  VOX_ASSIGN_OR_RETURN(AtomicFile f, AtomicFile::Create(path));
  VOX_RETURN_IF_ERROR(WriteBytes(f.temp_path(), path, bytes));
  files_.push_back(std::move(f));
  return OkStatus();
}

Status OutputGroup::Commit() {
  for (const auto& [path, bytes] : special_) {
    Status s = WriteBytes(path, path, bytes);
    if (!s.ok()) {
      files_.clear();  // removes the temporaries: nothing is published
      return s;
    }
  }
  special_.clear();
  // Sync every temporary before the first rename, so a failure here also
  // publishes nothing.
  for (AtomicFile& f : files_) {
    Status s = f.Sync();
    if (!s.ok()) {
      files_.clear();
      return s;
    }
  }
  std::lock_guard<std::mutex> publishing(TemporaryMutex());  // never half a group
  for (AtomicFile& f : files_) VOX_RETURN_IF_ERROR(f.Commit());
  files_.clear();
  return OkStatus();
}

}  // namespace vox
