// An LD_PRELOAD library that injects write-side faults into a tool, for the
// fault tests (write_fault_test.cpp). Configured by the environment:
//   VOX_FAULT       write | short | fsync | rename
//   VOX_FAULT_PATH  the fault applies to files whose path contains this
//                   (write, short, fsync: the descriptor's file; rename: the
//                   source or the destination)
//   VOX_FAULT_ERRNO the errno to fail with: ENOSPC, EIO, EDQUOT (default EIO)
//   VOX_FAULT_AFTER write: bytes written to matching files before the disk
//                   "fills" (the write that crosses it is cut short, the
//                   next fails); default 0
// `short` makes every matching write(2)/writev(2)/pwrite(2) write at most
// half of what was asked (at least one byte): correct output needs the
// caller's loop. Each injected fault prints one line to stderr, so tests can
// tell a fault that was never reached from one that was handled.
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/uio.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>

namespace {

struct Config {
  int mode = 0;  // 0 none, 1 write, 2 short, 3 fsync, 4 rename
  const char* path = nullptr;
  int err = EIO;
  uint64_t after = 0;
};

const Config& Cfg() {
  static const Config c = [] {
    Config c;
    const char* m = getenv("VOX_FAULT");
    if (m == nullptr) return c;
    if (!strcmp(m, "write")) c.mode = 1;
    else if (!strcmp(m, "short")) c.mode = 2;
    else if (!strcmp(m, "fsync")) c.mode = 3;
    else if (!strcmp(m, "rename")) c.mode = 4;
    c.path = getenv("VOX_FAULT_PATH");
    if (const char* e = getenv("VOX_FAULT_ERRNO")) {
      if (!strcmp(e, "ENOSPC")) c.err = ENOSPC;
      else if (!strcmp(e, "EDQUOT")) c.err = EDQUOT;
      else c.err = EIO;
    }
    if (const char* a = getenv("VOX_FAULT_AFTER")) c.after = strtoull(a, nullptr, 10);
    return c;
  }();
  return c;
}

std::atomic<uint64_t> g_written{0};
std::atomic<bool> g_reported{false};

bool PathMatches(const char* p) {
  const Config& c = Cfg();
  return p != nullptr && (c.path == nullptr || strstr(p, c.path) != nullptr);
}

bool FdMatches(int fd) {
  char link[64], target[4096];
  snprintf(link, sizeof link, "/proc/self/fd/%d", fd);
  ssize_t n = readlink(link, target, sizeof target - 1);
  if (n <= 0) return false;
  target[n] = '\0';
  return PathMatches(target);
}

void Report(const char* what) {
  if (!g_reported.exchange(true)) {
    char line[256];
    int n = snprintf(line, sizeof line, "fault_shim: injected %s (%s)\n", what, strerror(Cfg().err));
    static auto real_write = reinterpret_cast<ssize_t (*)(int, const void*, size_t)>(dlsym(RTLD_NEXT, "write"));
    real_write(2, line, size_t(n));
  }
}

// How many of `n` bytes a matching write may write: -1 to fail with errno.
ssize_t Allowance(int fd, size_t n) {
  const Config& c = Cfg();
  if ((c.mode != 1 && c.mode != 2) || n == 0 || !FdMatches(fd)) return ssize_t(n);
  if (c.mode == 2) return ssize_t(n > 1 ? n / 2 : n);
  const uint64_t done = g_written.load();
  if (done >= c.after) {
    Report("write failure");
    errno = c.err;
    return -1;
  }
  const uint64_t left = c.after - done;
  return ssize_t(n < left ? n : left);
}

template <typename F>
F Real(const char* name) {
  return reinterpret_cast<F>(dlsym(RTLD_NEXT, name));
}

}  // namespace

extern "C" {

ssize_t write(int fd, const void* buf, size_t n) {
  static auto real = Real<ssize_t (*)(int, const void*, size_t)>("write");
  const ssize_t allow = Allowance(fd, n);
  if (allow < 0) return -1;
  const ssize_t r = real(fd, buf, size_t(allow));
  if (r > 0 && Cfg().mode == 1 && FdMatches(fd)) g_written += uint64_t(r);
  return r;
}

ssize_t pwrite64(int fd, const void* buf, size_t n, off_t off) {
  static auto real = Real<ssize_t (*)(int, const void*, size_t, off_t)>("pwrite64");
  const ssize_t allow = Allowance(fd, n);
  if (allow < 0) return -1;
  const ssize_t r = real(fd, buf, size_t(allow), off);
  if (r > 0 && Cfg().mode == 1 && FdMatches(fd)) g_written += uint64_t(r);
  return r;
}

ssize_t pwrite(int fd, const void* buf, size_t n, off_t off) { return pwrite64(fd, buf, n, off); }

ssize_t writev(int fd, const struct iovec* iov, int cnt) {
  static auto real = Real<ssize_t (*)(int, const struct iovec*, int)>("writev");
  size_t total = 0;
  for (int i = 0; i < cnt; ++i) total += iov[i].iov_len;
  const ssize_t allow = Allowance(fd, total);
  if (allow < 0) return -1;
  if (size_t(allow) == total) {
    const ssize_t r = real(fd, iov, cnt);
    if (r > 0 && Cfg().mode == 1 && FdMatches(fd)) g_written += uint64_t(r);
    return r;
  }
  // Cut short: write the first `allow` bytes of the vector.
  struct iovec part[64];
  int k = 0;
  size_t left = size_t(allow);
  for (int i = 0; i < cnt && k < 64 && left > 0; ++i, ++k) {
    part[k] = iov[i];
    if (part[k].iov_len > left) part[k].iov_len = left;
    left -= part[k].iov_len;
  }
  const ssize_t r = real(fd, part, k);
  if (r > 0 && Cfg().mode == 1) g_written += uint64_t(r);
  return r;
}

int fsync(int fd) {
  static auto real = Real<int (*)(int)>("fsync");
  if (Cfg().mode == 3 && FdMatches(fd)) {
    Report("fsync failure");
    errno = Cfg().err;
    return -1;
  }
  return real(fd);
}

int fdatasync(int fd) {
  static auto real = Real<int (*)(int)>("fdatasync");
  if (Cfg().mode == 3 && FdMatches(fd)) {
    Report("fdatasync failure");
    errno = Cfg().err;
    return -1;
  }
  return real(fd);
}

int rename(const char* from, const char* to) {
  static auto real = Real<int (*)(const char*, const char*)>("rename");
  if (Cfg().mode == 4 && (PathMatches(from) || PathMatches(to))) {
    Report("rename failure");
    errno = Cfg().err;
    return -1;
  }
  return real(from, to);
}

int renameat(int fd1, const char* from, int fd2, const char* to) {
  static auto real = Real<int (*)(int, const char*, int, const char*)>("renameat");
  if (Cfg().mode == 4 && (PathMatches(from) || PathMatches(to))) {
    Report("rename failure");
    errno = Cfg().err;
    return -1;
  }
  return real(fd1, from, fd2, to);
}

int renameat2(int fd1, const char* from, int fd2, const char* to, unsigned flags) {
  static auto real = Real<int (*)(int, const char*, int, const char*, unsigned)>("renameat2");
  if (Cfg().mode == 4 && (PathMatches(from) || PathMatches(to))) {
    Report("rename failure");
    errno = Cfg().err;
    return -1;
  }
  return real(fd1, from, fd2, to, flags);
}

}  // extern "C"
