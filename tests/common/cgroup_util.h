// vox::testing::RunInMemoryCgroup: runs a program in a fresh memory cgroup
// with a byte limit, as Slurm's --mem or a container would, and reports its
// exit, whether the kernel's OOM killer ended it, its peak charge (v1
// memory.max_usage_in_bytes, v2 memory.peak: anonymous memory and the page
// cache it brought in) and how often it hit the limit. The cgroup is created
// under the memory hierarchy's mount point (v1 .../memory/NAME, v2 .../NAME)
// and removed afterwards. Tests call VOX_REQUIRE_MEMORY_CGROUP() first: it
// skips them, saying why, where no writable memory cgroup exists (not root,
// read-only cgroupfs, v2 without the memory controller).
//
// Thread safety: thread-safe (each run makes its own cgroup); forks, so call
// it from a test's main thread.
#ifndef VOX_TESTS_COMMON_CGROUP_UTIL_H_
#define VOX_TESTS_COMMON_CGROUP_UTIL_H_

#include <fcntl.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <csignal>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "core/util/status.h"

namespace vox::testing {

// A whole text file (a log, a --stats JSON); empty when it cannot be read.
inline std::string ReadAll(const std::string& path) {
  std::ifstream in(path);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

struct CgroupRunOptions {
  uint64_t limit_bytes = 0;      // 0: no limit (the run is only measured)
  bool drop_page_cache = false;  // sync and drop the kernel's clean page cache first (a cold run)
  std::string stdout_path;       // empty: /dev/null
  std::string stderr_path;       // empty: /dev/null
};

struct CgroupRunResult {
  int exit_code = -1;     // when the program exited normally
  int term_signal = 0;    // when a signal ended it
  bool oom_killed = false;  // the cgroup's OOM killer ended it
  uint64_t peak_bytes = 0;  // largest charge seen (0 where the kernel does not report it)
  uint64_t failcnt = 0;     // times the charge hit the limit (v1 failcnt, of memory or memory+swap; v2 events "max")
  bool page_cache_dropped = false;
  int version = 0;          // cgroup version used: 1 or 2
  std::string Describe() const {
    std::ostringstream o;
    if (term_signal != 0)
      o << "killed by signal " << term_signal << (oom_killed ? " (OOM killer)" : "");
    else
      o << "exit " << exit_code;
    o << ", peak " << peak_bytes / (1 << 20) << " MiB, failcnt " << failcnt;
    return o.str();
  }
};

namespace cgroup_internal {

inline bool ReadText(const std::string& path, std::string* out) {
  std::ifstream in(path);
  if (!in) return false;
  std::ostringstream ss;
  ss << in.rdbuf();
  *out = ss.str();
  return true;
}

inline bool WriteText(const std::string& path, const std::string& text) {
  int fd = ::open(path.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) return false;
  bool ok = ::write(fd, text.data(), text.size()) == ssize_t(text.size());
  ok = (::close(fd) == 0) && ok;
  return ok;
}

inline uint64_t ReadNumber(const std::string& path) {
  std::string s;
  if (!ReadText(path, &s)) return 0;
  return std::strtoull(s.c_str(), nullptr, 10);
}

// The value of `key` in a "key value" per line file (memory.events,
// oom_control, /proc/meminfo).
inline uint64_t ReadKey(const std::string& path, const std::string& key) {
  std::string s;
  if (!ReadText(path, &s)) return 0;
  std::istringstream in(s);
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string k;
    uint64_t v = 0;
    if (ls >> k >> v && k == key) return v;
  }
  return 0;
}

struct Hierarchy {
  int version = 0;    // 0: none usable
  std::string mount;  // where the memory hierarchy is mounted
  std::string why;    // why none is usable
};

// The memory hierarchy to make test cgroups in: v1's memory mount, else a v2
// mount whose root offers the memory controller to its children.
inline Hierarchy FindHierarchy() {
  Hierarchy h;
  std::string mountinfo;
  if (!ReadText("/proc/self/mountinfo", &mountinfo)) {
    h.why = "cannot read /proc/self/mountinfo";
    return h;
  }
  std::istringstream in(mountinfo);
  std::string line, v2_mount;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::vector<std::string> f;
    std::string w;
    while (ls >> w) f.push_back(w);
    size_t dash = 0;
    while (dash < f.size() && f[dash] != "-") ++dash;
    if (f.size() < 5 || dash + 3 >= f.size()) continue;
    const std::string& type = f[dash + 1];
    const std::string opts = "," + f[dash + 3] + ",";
    if (type == "cgroup" && opts.find(",memory,") != std::string::npos) {
      h.version = 1;
      h.mount = f[4];
      break;
    }
    if (type == "cgroup2" && v2_mount.empty()) v2_mount = f[4];
  }
  if (h.version == 0 && !v2_mount.empty()) {
    std::string controllers;
    ReadText(v2_mount + "/cgroup.controllers", &controllers);
    if (controllers.find("memory") == std::string::npos) {
      h.why = "the cgroup v2 hierarchy at " + v2_mount + " has no memory controller";
      return h;
    }
    std::string subtree;
    ReadText(v2_mount + "/cgroup.subtree_control", &subtree);
    if (subtree.find("memory") == std::string::npos &&
        !WriteText(v2_mount + "/cgroup.subtree_control", "+memory")) {
      h.why = "cannot enable the memory controller in " + v2_mount + "/cgroup.subtree_control: " +
              std::strerror(errno);
      return h;
    }
    h.version = 2;
    h.mount = v2_mount;
  }
  if (h.version == 0) {
    h.why = "no memory cgroup hierarchy is mounted";
    return h;
  }
  if (::access(h.mount.c_str(), W_OK) != 0) {
    h.why = "the memory cgroup hierarchy at " + h.mount + " is not writable (" + std::strerror(errno) +
            "); run as root with a writable cgroupfs";
    h.version = 0;
  }
  return h;
}

}  // namespace cgroup_internal

// Empty when RunInMemoryCgroup can work here, else why not. It makes and
// removes a probe cgroup to be sure.
inline std::string MemoryCgroupUnavailable() {
  cgroup_internal::Hierarchy h = cgroup_internal::FindHierarchy();
  if (h.version == 0) return h.why;
  const std::string dir = h.mount + "/vox_probe_" + std::to_string(::getpid());
  if (::mkdir(dir.c_str(), 0755) != 0 && errno != EEXIST)
    return "cannot create a cgroup in " + h.mount + ": " + std::strerror(errno);
  const char* file = h.version == 1 ? "/memory.limit_in_bytes" : "/memory.max";
  const bool ok = cgroup_internal::WriteText(dir + file, std::to_string(uint64_t(1) << 30));
  const int err = errno;
  ::rmdir(dir.c_str());
  if (!ok) return "cannot set " + dir + file + ": " + std::strerror(err);
  return "";
}

#define VOX_REQUIRE_MEMORY_CGROUP()                                              \
  do {                                                                           \
    static const std::string vox_cgroup_why = ::vox::testing::MemoryCgroupUnavailable(); \
    if (!vox_cgroup_why.empty())                                                 \
      GTEST_SKIP() << "no writable memory cgroup: " << vox_cgroup_why;           \
  } while (0)

// Runs argv[0] (a path) with arguments argv[1..] in a new memory cgroup.
inline StatusOr<CgroupRunResult> RunInMemoryCgroup(const std::vector<std::string>& argv,
                                                   const CgroupRunOptions& options) {
  using namespace cgroup_internal;
  if (argv.empty()) return InvalidArgumentError("RunInMemoryCgroup: empty command");
  Hierarchy h = FindHierarchy();
  if (h.version == 0) return UnsupportedError("no writable memory cgroup: " + h.why);
  static std::atomic<int> counter{0};
  const std::string dir = h.mount + "/vox_test_" + std::to_string(::getpid()) + "_" +
                          std::to_string(counter++);
  if (::mkdir(dir.c_str(), 0755) != 0)
    return IoError("cannot create cgroup " + dir + ": " + std::strerror(errno));
  CgroupRunResult r;
  r.version = h.version;
  auto fail = [&](const std::string& what) {
    Status s = IoError(what + ": " + std::strerror(errno));
    ::rmdir(dir.c_str());
    return s;
  };
  if (options.limit_bytes != 0) {
    const std::string limit = std::to_string(options.limit_bytes);
    if (h.version == 1) {
      if (!WriteText(dir + "/memory.limit_in_bytes", limit)) return fail("cannot set " + dir + "/memory.limit_in_bytes");
      // With swap, memory+swap must be capped too, or the program swaps
      // instead of dying. (Without swap, leave it: some kernels then stop
      // counting failcnt.)
      if (ReadKey("/proc/meminfo", "SwapTotal:") != 0 &&
          ::access((dir + "/memory.memsw.limit_in_bytes").c_str(), F_OK) == 0)
        WriteText(dir + "/memory.memsw.limit_in_bytes", limit);
    } else {
      if (!WriteText(dir + "/memory.max", limit)) return fail("cannot set " + dir + "/memory.max");
      if (::access((dir + "/memory.swap.max").c_str(), F_OK) == 0) WriteText(dir + "/memory.swap.max", "0");
    }
  }
  if (options.drop_page_cache) {
    ::sync();
    r.page_cache_dropped = WriteText("/proc/sys/vm/drop_caches", "1");
  }
  // Everything the child needs, made before fork (the child only calls
  // async-signal-safe functions).
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  const std::string out = options.stdout_path.empty() ? "/dev/null" : options.stdout_path;
  const std::string err = options.stderr_path.empty() ? "/dev/null" : options.stderr_path;
  int go[2];
  if (::pipe2(go, O_CLOEXEC) != 0) return fail("pipe");
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(go[0]);
    ::close(go[1]);
    return fail("fork");
  }
  if (pid == 0) {
    ::close(go[1]);
    char c;
    // Wait until the parent has moved this process into the cgroup.
    if (::read(go[0], &c, 1) != 1) ::_exit(126);
    int o = ::open(out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    int e = ::open(err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (o < 0 || e < 0 || ::dup2(o, 1) < 0 || ::dup2(e, 2) < 0) ::_exit(126);
    ::execv(args[0], args.data());
    ::_exit(127);
  }
  ::close(go[0]);
  const bool moved = WriteText(dir + "/cgroup.procs", std::to_string(pid));
  const int move_errno = errno;
  if (moved) {
    const char c = 'g';
    (void)!::write(go[1], &c, 1);
  }
  ::close(go[1]);  // without the byte, the child exits 126
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (!moved) {
    ::rmdir(dir.c_str());
    return IoError("cannot move pid " + std::to_string(pid) + " into " + dir + "/cgroup.procs: " +
                   std::strerror(move_errno));
  }
  if (WIFEXITED(status)) r.exit_code = WEXITSTATUS(status);
  if (WIFSIGNALED(status)) r.term_signal = WTERMSIG(status);
  uint64_t oom_kills = 0;
  if (h.version == 1) {
    r.peak_bytes = ReadNumber(dir + "/memory.max_usage_in_bytes");
    // With memsw capped too, a failing charge may count there instead.
    r.failcnt = std::max(ReadNumber(dir + "/memory.failcnt"), ReadNumber(dir + "/memory.memsw.failcnt"));
    oom_kills = ReadKey(dir + "/memory.oom_control", "oom_kill");
  } else {
    r.peak_bytes = ReadNumber(dir + "/memory.peak");
    r.failcnt = ReadKey(dir + "/memory.events", "max");
    oom_kills = ReadKey(dir + "/memory.events", "oom_kill");
  }
  r.oom_killed = r.term_signal == SIGKILL && (oom_kills > 0 || r.failcnt > 0);
  // The charge of the page cache left behind moves to the parent; rmdir can
  // race with the exiting task's teardown, so retry briefly.
  for (int i = 0; i < 100 && ::rmdir(dir.c_str()) != 0 && errno == EBUSY; ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  if (::access(dir.c_str(), F_OK) == 0)
    return IoError("cannot remove cgroup " + dir + ": " + std::strerror(errno));
  return r;
}

}  // namespace vox::testing

#endif  // VOX_TESTS_COMMON_CGROUP_UTIL_H_
