#include "core/util/file.h"

#include <dirent.h>
#include <fcntl.h>
#include <setjmp.h>
#include <signal.h>
#include <stdio.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <random>
#include <sstream>
#include <string>

namespace vox {
namespace {

// SIGBUS guard. A thread copying out of a mapping sets tls_bus_jmp; the
// handler jumps back to it. A SIGBUS anywhere else goes to the previous
// disposition, so the guard changes nothing outside storage's copies.
thread_local sigjmp_buf* tls_bus_jmp = nullptr;
struct sigaction g_previous_bus_action;
std::once_flag g_bus_handler_once;

void BusHandler(int sig, siginfo_t* info, void* ucontext) {
  sigjmp_buf* jb = tls_bus_jmp;
  if (jb != nullptr) {
    tls_bus_jmp = nullptr;
    siglongjmp(*jb, 1);
  }
  // Not ours: hand over to whatever was installed before.
  if (g_previous_bus_action.sa_flags & SA_SIGINFO) {
    if (g_previous_bus_action.sa_sigaction != nullptr) {
      g_previous_bus_action.sa_sigaction(sig, info, ucontext);
      return;
    }
  } else if (g_previous_bus_action.sa_handler != SIG_DFL &&
             g_previous_bus_action.sa_handler != SIG_IGN) {
    g_previous_bus_action.sa_handler(sig);
    return;
  }
  // Default action: restore it and re-raise, terminating the process as it
  // would have without us (a faulting access would also repeat on return).
  signal(SIGBUS, SIG_DFL);
  raise(SIGBUS);
}

void InstallBusHandler() {
  std::call_once(g_bus_handler_once, [] {
    struct sigaction sa;
    std::memset(&sa, 0, sizeof(sa));
    sa.sa_sigaction = BusHandler;
    sa.sa_flags = SA_SIGINFO | SA_NODEFER;
    sigemptyset(&sa.sa_mask);
    sigaction(SIGBUS, &sa, &g_previous_bus_action);
  });
}

// memcpy that returns false instead of dying when the source page is gone.
// noinline: the setjmp frame must be this function's.
[[gnu::noinline]] bool GuardedCopy(void* dst, const void* src, size_t n) {
  sigjmp_buf jb;
  if (sigsetjmp(jb, 0) != 0) {
    // SA_NODEFER: SIGBUS is not blocked in this thread after the jump.
    return false;
  }
  tls_bus_jmp = &jb;
  std::atomic_signal_fence(std::memory_order_seq_cst);
  std::memcpy(dst, src, n);
  std::atomic_signal_fence(std::memory_order_seq_cst);
  tls_bus_jmp = nullptr;
  return true;
}

// The size of open file `fd` now (fstat), for CurrentSize.
StatusOr<uint64_t> SizeOnDisk(int fd, const std::string& path) {
  struct stat st;
  if (fstat(fd, &st) != 0) return ErrnoError("cannot stat", path, errno);
  return uint64_t(st.st_size);
}

Status RangeError(const std::string& path, uint64_t offset, size_t n, uint64_t size) {
  return CorruptionError("read of bytes [" + std::to_string(offset) + ", " +
                         std::to_string(offset + n) + ") past the end of '" + path + "' (" +
                         std::to_string(size) + " bytes)");
}

class MmapFile : public RandomAccessFile {
 public:
  MmapFile(std::string path, int fd, const uint8_t* base, uint64_t size, bool check)
      : path_(std::move(path)), fd_(fd), base_(base), size_(size), check_(check) {}
  ~MmapFile() override {
    if (base_ != nullptr) munmap(const_cast<uint8_t*>(base_), size_);
    if (fd_ >= 0) close(fd_);
  }
  const std::string& path() const override { return path_; }
  uint64_t size() const override { return size_; }

  Status Read(uint64_t offset, size_t n, uint8_t* scratch) const override {
    if (offset > size_ || n > size_ - offset) return RangeError(path_, offset, n, size_);
    if (n == 0) return OkStatus();
    if (check_) {
      VOX_ASSIGN_OR_RETURN(uint64_t now, CurrentSize());
      if (now < offset + n)
        return IoError("'" + path_ + "' shrank from " + std::to_string(size_) + " to " +
                       std::to_string(now) + " bytes while open (needed bytes up to " +
                       std::to_string(offset + n) + ")");
    }
    if (!GuardedCopy(scratch, base_ + offset, n))
      return IoError("'" + path_ + "': SIGBUS reading mapped bytes [" + std::to_string(offset) +
                     ", " + std::to_string(offset + n) +
                     "): the file shrank or its storage failed while open");
    return OkStatus();
  }

  StatusOr<uint64_t> CurrentSize() const override { return SizeOnDisk(fd_, path_); }

 private:
  std::string path_;
  int fd_;
  const uint8_t* base_;
  uint64_t size_;
  bool check_;
};

class PreadFile : public RandomAccessFile {
 public:
  PreadFile(std::string path, int fd, uint64_t size)
      : path_(std::move(path)), fd_(fd), size_(size) {}
  ~PreadFile() override { close(fd_); }
  const std::string& path() const override { return path_; }
  uint64_t size() const override { return size_; }

  Status Read(uint64_t offset, size_t n, uint8_t* scratch) const override {
    if (offset > size_ || n > size_ - offset) return RangeError(path_, offset, n, size_);
    size_t done = 0;
    while (done < n) {
      ssize_t r = pread(fd_, scratch + done, n - done, off_t(offset + done));
      if (r < 0) {
        if (errno == EINTR) continue;
        return ErrnoError("cannot read bytes [" + std::to_string(offset) + ", " +
                              std::to_string(offset + n) + ") of",
                          path_, errno);
      }
      if (r == 0) {  // end of file before the end of a range inside size(): it shrank
        auto now = CurrentSize();
        return IoError("'" + path_ + "' shrank from " + std::to_string(size_) + " to " +
                       (now.ok() ? std::to_string(*now) : std::string("?")) +
                       " bytes while open (needed bytes up to " + std::to_string(offset + n) +
                       ")");
      }
      done += size_t(r);
    }
    return OkStatus();
  }

  StatusOr<uint64_t> CurrentSize() const override { return SizeOnDisk(fd_, path_); }

 private:
  std::string path_;
  int fd_;
  uint64_t size_;
};

class MemoryFile : public RandomAccessFile {
 public:
  MemoryFile(std::string name, std::string contents)
      : name_(std::move(name)), data_(std::move(contents)) {}
  const std::string& path() const override { return name_; }
  uint64_t size() const override { return data_.size(); }
  Status Read(uint64_t offset, size_t n, uint8_t* scratch) const override {
    if (offset > data_.size() || n > data_.size() - offset)
      return RangeError(name_, offset, n, data_.size());
    if (n > 0) std::memcpy(scratch, data_.data() + offset, n);
    return OkStatus();
  }

 private:
  std::string name_;
  std::string data_;
};

}  // namespace

StatusOr<uint64_t> ProcessIoBytes() {
  FILE* f = std::fopen("/proc/self/io", "re");
  if (f == nullptr)
    return UnsupportedError("cannot open '/proc/self/io': " + std::string(std::strerror(errno)));
  char line[256];
  unsigned long long v = 0;
  bool found = false;
  while (std::fgets(line, sizeof(line), f) != nullptr) {
    if (std::sscanf(line, "read_bytes: %llu", &v) == 1) {
      found = true;
      break;
    }
  }
  std::fclose(f);
  if (!found) return UnsupportedError("'/proc/self/io' has no read_bytes line");
  return uint64_t(v);
}

Status ErrnoError(const std::string& what, const std::string& path, int err) {
  std::string m = what + " '" + path + "': " + std::strerror(err);
  if (err == ENOSPC || err == EDQUOT || err == EFBIG) return ResourceExhaustedError(m);
  if (err == ENOENT) return NotFoundError(m);
  return IoError(m);
}

namespace {
// Opens a regular file read-only; its fd and stat. Opened with O_NONBLOCK
// (cleared once it is known to be a regular file), so a FIFO put in place
// of a store file is refused at once instead of blocking open() for a writer.
Status OpenRegular(const std::string& path, int* fd_out, struct stat* st) {
  int fd = open(path.c_str(), O_RDONLY | O_CLOEXEC | O_NONBLOCK);
  if (fd < 0) return ErrnoError("cannot open", path, errno);
  if (fstat(fd, st) != 0) {
    int err = errno;
    close(fd);
    return ErrnoError("cannot stat", path, err);
  }
  if (!S_ISREG(st->st_mode)) {
    close(fd);
    return IoError("'" + path + "' is not a regular file (" +
                   (S_ISFIFO(st->st_mode)  ? "a FIFO"
                    : S_ISCHR(st->st_mode) ? "a character device"
                    : S_ISDIR(st->st_mode) ? "a directory"
                                           : "a special file") +
                   ")");
  }
  fcntl(fd, F_SETFL, fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  *fd_out = fd;
  return OkStatus();
}
}  // namespace

StatusOr<std::unique_ptr<RandomAccessFile>> OpenPreadFile(const std::string& path,
                                                          bool random_access) {
  int fd = -1;
  struct stat st;
  VOX_RETURN_IF_ERROR(OpenRegular(path, &fd, &st));
  if (random_access) posix_fadvise(fd, 0, 0, POSIX_FADV_RANDOM);  // a hint: failure is harmless
  return std::unique_ptr<RandomAccessFile>(new PreadFile(path, fd, uint64_t(st.st_size)));
}

StatusOr<std::unique_ptr<RandomAccessFile>> OpenMmapFile(const std::string& path,
                                                         bool check_size_each_read,
                                                         bool random_access) {
  int fd = -1;
  struct stat st;
  VOX_RETURN_IF_ERROR(OpenRegular(path, &fd, &st));
  const uint8_t* base = nullptr;
  if (st.st_size > 0) {
    void* p = mmap(nullptr, size_t(st.st_size), PROT_READ, MAP_SHARED, fd, 0);
    if (p == MAP_FAILED) {
      int err = errno;
      close(fd);
      return ErrnoError("cannot mmap", path, err);
    }
    base = static_cast<const uint8_t*>(p);
    if (random_access) madvise(p, size_t(st.st_size), MADV_RANDOM);  // a hint
  }
  InstallBusHandler();
  return std::unique_ptr<RandomAccessFile>(
      new MmapFile(path, fd, base, uint64_t(st.st_size), check_size_each_read));
}

std::unique_ptr<RandomAccessFile> NewMemoryFile(std::string name, std::string contents) {
  return std::make_unique<MemoryFile>(std::move(name), std::move(contents));
}

Status FaultInjectionFile::Read(uint64_t offset, size_t n, uint8_t* scratch) const {
  int64_t left = fail_after_.load();
  if (left == 0) return IoError("'" + path() + "': injected read error");
  const uint64_t every = fail_every_.load();
  if (every > 0 && (calls_.fetch_add(1) + 1) % every == 0) {
    injected_.fetch_add(1);
    return IoError("'" + path() + "': injected read error");
  }
  if (left > 0) fail_after_.fetch_sub(1);
  ++reads_;
  VOX_RETURN_IF_ERROR(base_->Read(offset, n, scratch));
  if (flip_offset_ >= offset && flip_offset_ < offset + n) scratch[flip_offset_ - offset] ^= flip_mask_;
  return OkStatus();
}

StatusOr<std::unique_ptr<WritableFile>> WritableFile::Create(const std::string& path) {
  int fd = open(path.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) return ErrnoError("cannot create", path, errno);
  return std::unique_ptr<WritableFile>(new WritableFile(path, fd));
}

StatusOr<std::unique_ptr<WritableFile>> WritableFile::OpenAppend(const std::string& path,
                                                                 uint64_t keep) {
  int fd = open(path.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) return ErrnoError("cannot open", path, errno);
  std::unique_ptr<WritableFile> f(new WritableFile(path, fd));
  if (ftruncate(fd, off_t(keep)) != 0 || lseek(fd, off_t(keep), SEEK_SET) < 0)
    return ErrnoError("cannot truncate", path, errno);
  f->size_ = keep;
  return f;
}

WritableFile::~WritableFile() {
  if (fd_ >= 0) close(fd_);
}

Status WritableFile::Append(const void* data, size_t n) {
  if (fd_ < 0) return InternalError("append to closed file '" + path_ + "'");
  buf_.append(static_cast<const char*>(data), n);
  size_ += n;
  if (buf_.size() >= (size_t(1) << 20)) return Flush();
  return OkStatus();
}

Status WritableFile::Flush() {
  size_t done = 0;
  while (done < buf_.size()) {
    ssize_t w = write(fd_, buf_.data() + done, buf_.size() - done);
    if (w < 0) {
      if (errno == EINTR) continue;
      int err = errno;
      buf_.clear();
      return ErrnoError("cannot write", path_, err);
    }
    done += size_t(w);
  }
  buf_.clear();
  return OkStatus();
}

Status WritableFile::Sync() {
  VOX_RETURN_IF_ERROR(Flush());
  if (fsync(fd_) != 0) return ErrnoError("cannot fsync", path_, errno);
  return OkStatus();
}

Status WritableFile::Close() {
  if (fd_ < 0) return OkStatus();
  Status s = Flush();
  if (close(fd_) != 0 && s.ok()) s = ErrnoError("cannot close", path_, errno);
  fd_ = -1;
  return s;
}

Status SyncDir(const std::string& dir) {
  int fd = open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return ErrnoError("cannot open directory", dir, errno);
  int r = fsync(fd);
  int err = errno;
  close(fd);
  if (r != 0) return ErrnoError("cannot fsync directory", dir, err);
  return OkStatus();
}

bool ProcessGone(long pid) {
  if (kill(pid_t(pid), 0) != 0 && errno == ESRCH) return true;
  // A zombie: the state after the command name (which may hold spaces and
  // parentheses) is 'Z'.
  std::ifstream in("/proc/" + std::to_string(pid) + "/stat");
  std::string stat;
  if (!std::getline(in, stat)) return false;
  const size_t paren = stat.rfind(')');
  return paren != std::string::npos && paren + 2 < stat.size() && stat[paren + 2] == 'Z';
}

void SplitPath(const std::string& path, std::string* dir, std::string* name) {
  const size_t slash = path.rfind('/');
  if (slash == std::string::npos) {
    *dir = ".";
    *name = path;
  } else {
    *dir = slash == 0 ? "/" : path.substr(0, slash);
    *name = path.substr(slash + 1);
  }
}

StatusOr<std::string> ReadTextFile(const std::string& path, uint64_t max_bytes) {
  const int fd = open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    if (errno == ENOENT) return NotFoundError(path + ": cannot open for reading");
    return ErrnoError("cannot open", path, errno);
  }
  const std::string too_large = path + ": larger than " + std::to_string(max_bytes >> 20) +
                                " MiB, the most a camera or scene file may hold";
  struct stat st;
  if (fstat(fd, &st) == 0 && S_ISREG(st.st_mode) && uint64_t(st.st_size) > max_bytes) {
    close(fd);
    return InvalidArgumentError(too_large);  // before reading a byte
  }
  std::string text;
  char buf[1 << 16];
  for (;;) {  // a pipe (--cam <(...)) has no size: read at most max_bytes + 1
    const ssize_t n = read(fd, buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) {
      const int err = errno;
      close(fd);
      return ErrnoError("cannot read", path, err);
    }
    if (n == 0) break;
    text.append(buf, size_t(n));
    if (text.size() > max_bytes) {
      close(fd);
      return InvalidArgumentError(too_large);
    }
  }
  close(fd);
  return text;
}

namespace {

std::string JoinPath(const std::string& dir, const std::string& name) {
  return (dir == "/" ? "" : dir) + "/" + name;
}

bool AllOf(const std::string& s, size_t from, bool (*accept)(char)) {
  for (size_t i = from; i < s.size(); ++i)
    if (!accept(s[i])) return false;
  return true;
}
bool IsAlnum(char c) {
  return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z');
}
bool IsLowerHex(char c) { return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'); }

// What kind of temporary `rest` (the entry's name after ".NAME.tmp-") names:
// its process id and whether it is a directory's; pid 0 when none.
struct TempName {
  long pid = 0;
  bool directory = false;
};
TempName ParseTempName(std::string rest) {
  const size_t dash = rest.find('-');
  if (dash == std::string::npos || dash == 0 || dash > 10) return {};
  if (rest.find_first_not_of("0123456789") != dash) return {};
  const long pid = std::strtol(rest.c_str(), nullptr, 10);
  if (rest.size() == dash + 7 && AllOf(rest, dash + 1, IsAlnum)) return {pid, false};
  if (rest.size() > 4 && rest.compare(rest.size() - 4, 4, ".old") == 0) rest.resize(rest.size() - 4);
  if (rest.size() == dash + 9 && AllOf(rest, dash + 1, IsLowerHex)) return {pid, true};
  return {};
}

}  // namespace

void RemoveStaleTemporaries(const std::string& dir, const std::string& name) {
  const std::string prefix = "." + name + ".tmp-";
  DIR* d = opendir(dir.c_str());
  if (d == nullptr) return;
  while (const dirent* e = readdir(d)) {
    const std::string entry = e->d_name;
    if (entry.compare(0, prefix.size(), prefix) != 0) continue;
    const TempName temp = ParseTempName(entry.substr(prefix.size()));
    if (temp.pid <= 0 || temp.pid == long(getpid())) continue;
    if (!ProcessGone(temp.pid)) continue;  // alive (or not ours to judge)
    const std::string path = JoinPath(dir, entry);
    struct stat st;
    if (lstat(path.c_str(), &st) != 0) continue;
    if (!temp.directory && S_ISREG(st.st_mode)) {
      unlink(path.c_str());
    } else if (temp.directory && S_ISDIR(st.st_mode)) {
      std::error_code ec;
      std::filesystem::remove_all(path, ec);
    }
  }
  closedir(d);
}

std::mutex& TemporaryMutex() {
  static std::mutex mu;
  return mu;
}

StatusOr<std::string> CreateTemporary(const std::string& target, bool directory) {
  std::lock_guard<std::mutex> creating(TemporaryMutex());
  std::string dir, name;
  SplitPath(target, &dir, &name);
  RemoveStaleTemporaries(dir, name);
  const std::string prefix =
      JoinPath(dir, "." + name + ".tmp-" + std::to_string(long(getpid())) + "-");
  if (directory) {
    std::random_device rd;
    char suffix[16];
    snprintf(suffix, sizeof(suffix), "%08x", unsigned(rd()));
    const std::string path = prefix + suffix;
    if (mkdir(path.c_str(), 0755) != 0)
      return ErrnoError("cannot create the temporary directory", path, errno);
    return path;
  }
  std::string path = prefix + "XXXXXX";
  const int fd = mkstemp(path.data());
  if (fd < 0) return ErrnoError("cannot create a temporary file beside", target, errno);
  const mode_t mask = umask(0);
  umask(mask);
  fchmod(fd, 0644 & ~mask);
  close(fd);
  return path;
}

}  // namespace vox
