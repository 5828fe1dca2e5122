#include "tools/python/ingest_process.h"

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <nlohmann/json.hpp>
#include <optional>
#include <string_view>

#include "tools/common/options.h"
#include "tools/common/signals.h"
#include "tools/common/supervisor.h"

namespace vox {
namespace {

// The child's descriptors: lines up to the parent, answers down from it.
constexpr int kUpFd = 3, kDownFd = 4;

bool WriteAll(int fd, std::string_view s) {
  while (!s.empty()) {
    const ssize_t n = write(fd, s.data(), s.size());
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) return false;
    s.remove_prefix(size_t(n));
  }
  return true;
}

// A descriptor moved to 10 or above (close-on-exec), so that dup2 onto 3 and
// 4 in the child cannot overwrite a source nor be a no-op.
int AboveTen(int fd) {
  if (fd >= 10) return fd;
  const int moved = fcntl(fd, F_DUPFD_CLOEXEC, 10);
  close(fd);
  return moved;
}

// --- the child ---------------------------------------------------------------

volatile sig_atomic_t g_stop = 0;
extern "C" void OnStopSignal(int) { g_stop = 1; }

// Progress over the pipes; each progress point waits for the parent's answer.
class PipeSink : public ProgressSink {
 public:
  PipeSink(int up, int down) : up_(up), down_(down), parent_(getppid()) {}
  void Message(std::string_view line) override {
    std::string text(line);
    for (char& c : text)
      if (c == '\n' || c == '\r') c = ' ';
    if (!WriteAll(up_, "M " + text + "\n")) stop_ = true;
  }
  void Progress(uint64_t done, uint64_t total, uint64_t voxels) override {
    if (stop_) return;
    if (!WriteAll(up_, "P " + std::to_string(done) + " " + std::to_string(total) + " " +
                           std::to_string(voxels) + "\n")) {
      stop_ = true;
      return;
    }
    char answer = 0;
    ssize_t n;
    while ((n = read(down_, &answer, 1)) < 0 && errno == EINTR && !g_stop) {
    }
    if (n != 1 || answer != 'c') stop_ = true;  // 's', the parent gone, or a signal
  }
  void Done() override {}
  bool Cancelled() override { return stop_ || g_stop || getppid() != parent_; }

 private:
  int up_, down_;
  pid_t parent_;
  bool stop_ = false;
};

nlohmann::json StatsJson(const IngestStats& s, const std::string& output) {
  nlohmann::json d;
  d["store"] = output;
  d["levels"] = s.meta.levels;
  d["brick_level"] = s.meta.brick_level;
  d["input_bytes"] = s.input_bytes;
  d["active_voxels"] = s.active_voxels;
  d["leaf_nodes"] = s.leaf_nodes;
  d["active_tiles"] = s.active_tiles;
  d["occupied_voxels"] = s.occupied_voxels;
  d["occupied_tile_voxels"] = s.occupied_tile_voxels;
  d["bricks"] = s.bricks;
  d["bbox_leaves_read"] = s.bbox_leaves_read;
  d["topology_bytes"] = s.topology_bytes;
  d["memory_budget"] = s.memory_budget;
  d["threads"] = s.threads;
  d["seconds"] = {{"open", s.seconds_open},
                  {"bbox", s.seconds_bbox},
                  {"bricks", s.seconds_bricks},
                  {"finish", s.seconds_finish},
                  {"total", s.seconds_total}};
  return d;
}

std::string ErrorLine(const Status& s) {
  return "E " + std::to_string(int(s.code())) + " " + nlohmann::json(s.message()).dump() + "\n";
}

// --- the parent --------------------------------------------------------------

struct ChildLines {
  std::optional<std::string> stats;  // R
  std::optional<Status> error;       // E
};

// Handles one line from the child; answers a progress point on `down`.
void HandleLine(std::string_view line, int down, ProgressSink* sink,
                const std::atomic<bool>* cancel, pid_t child, bool* stopping,
                ChildLines* got) {
  if (line.size() < 2) return;
  const std::string_view rest = line.substr(2);
  switch (line[0]) {
    case 'P': {
      unsigned long long done = 0, total = 0, voxels = 0;
      if (!*stopping &&
          std::sscanf(std::string(rest).c_str(), "%llu %llu %llu", &done, &total, &voxels) == 3 &&
          sink)
        sink->Progress(done, total, voxels);
      if (!*stopping && (cancel->load() || (sink && sink->Cancelled()))) {
        *stopping = true;
        kill(child, SIGTERM);
      }
      WriteAll(down, *stopping ? "s" : "c");
      break;
    }
    case 'M':
      if (sink && !*stopping) sink->Message(rest);
      break;
    case 'R':
      got->stats = std::string(rest);
      break;
    case 'E': {
      const size_t space = rest.find(' ');
      std::string message = "the ingest child process sent a malformed error";
      int code = int(StatusCode::kInternal);
      try {
        code = std::stoi(std::string(rest.substr(0, space)));
        message = nlohmann::json::parse(rest.substr(space + 1)).get<std::string>();
      } catch (const std::exception&) {
      }
      got->error = Status(StatusCode(code), message);
      break;
    }
    default:
      break;
  }
}

}  // namespace

int RunIngestChild(const std::vector<std::string>& args) {
  if (args.size() < 5) return 2;
  const int up = std::atoi(args[0].c_str()), down = std::atoi(args[1].c_str());
  IngestCommand c;
  c.quiet = true;
  c.options.input = args[2];
  c.options.output = args[3];
  c.options.command_line = args[4];
  for (size_t i = 5; i < args.size(); ++i) {
    const std::string& flag = args[i];
    std::string value;
    if (ArityOf(IngestOptionTable(), flag) == FlagArity::kValue && i + 1 < args.size())
      value = args[++i];
    if (Status s = ApplyIngestFlag(&c, flag, value); !s.ok())
      return WriteAll(up, ErrorLine(s)) ? 0 : 1;
  }
  struct sigaction sa;
  std::memset(&sa, 0, sizeof sa);
  sa.sa_handler = OnStopSignal;  // no SA_RESTART: a wait for the parent's answer ends
  sigemptyset(&sa.sa_mask);
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) sigaction(sig, &sa, nullptr);
  signal(SIGPIPE, SIG_IGN);
  PipeSink pipe_sink(up, down);
  // The tool's test hooks (VOX_INGEST_TEST_CRASH...): a crash at a known point.
  const std::unique_ptr<ProgressSink> hook = MakeTestHookProgress(&pipe_sink);
  auto stats = Ingest(c.options, c.limits, hook ? hook.get() : &pipe_sink);
  const bool sent = stats.ok()
                        ? WriteAll(up, "R " + StatsJson(*stats, c.options.output).dump() + "\n")
                        : WriteAll(up, ErrorLine(stats.status()));
  return sent ? 0 : 1;
}

StatusOr<std::string> RunIngestChildProcess(const std::vector<std::string>& argv,
                                            const std::vector<std::string>& env,
                                            const IngestChildRequest& request,
                                            ProgressSink* sink,
                                            const std::atomic<bool>* cancel) {
  int up[2], down[2];
  if (pipe2(up, O_CLOEXEC) != 0)
    return Status(StatusCode::kInternal, std::string("pipe: ") + std::strerror(errno));
  if (pipe2(down, O_CLOEXEC) != 0) {
    const int err = errno;
    close(up[0]);
    close(up[1]);
    return Status(StatusCode::kInternal, std::string("pipe: ") + std::strerror(err));
  }
  up[1] = AboveTen(up[1]);
  down[0] = AboveTen(down[0]);
  std::vector<std::string> all = argv;
  for (const std::string& s : {std::to_string(kUpFd), std::to_string(kDownFd), request.input,
                               request.output, request.command_line})
    all.push_back(s);
  all.insert(all.end(), request.flags.begin(), request.flags.end());
  std::vector<char*> args, envp;
  for (std::string& s : all) args.push_back(s.data());
  args.push_back(nullptr);
  std::vector<std::string> env_copy = env;
  for (std::string& s : env_copy) envp.push_back(s.data());
  envp.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_adddup2(&actions, up[1], kUpFd);
  posix_spawn_file_actions_adddup2(&actions, down[0], kDownFd);
  pid_t child = -1;
  const int rc = posix_spawn(&child, args[0], &actions, nullptr, args.data(), envp.data());
  posix_spawn_file_actions_destroy(&actions);
  close(up[1]);
  close(down[0]);
  if (rc != 0) {
    close(up[0]);
    close(down[1]);
    return Status(StatusCode::kInternal, "cannot start the ingest child process (" + argv[0] +
                                             "): " + std::strerror(rc));
  }

  bool stopping = false;
  ChildLines got;
  std::string buffer;
  for (;;) {
    pollfd p{up[0], POLLIN, 0};
    const int ready = poll(&p, 1, 50);
    if (ready < 0 && errno != EINTR) break;
    if (!stopping && cancel->load()) {  // a KeyboardInterrupt between progress points
      stopping = true;
      kill(child, SIGTERM);
    }
    if (ready <= 0) continue;
    char chunk[4096];
    const ssize_t n = read(up[0], chunk, sizeof chunk);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;  // the child closed its end: it exited
    buffer.append(chunk, size_t(n));
    for (size_t end; (end = buffer.find('\n')) != std::string::npos;) {
      HandleLine(std::string_view(buffer).substr(0, end), down[1], sink, cancel, child, &stopping,
                 &got);
      buffer.erase(0, end + 1);
    }
  }
  close(up[0]);
  close(down[1]);
  int status = 0;
  while (waitpid(child, &status, 0) < 0 && errno == EINTR) {
  }
  const bool exited_0 = WIFEXITED(status) && WEXITSTATUS(status) == 0;
  if (got.stats && exited_0) return *got.stats;
  if (got.error && exited_0) return *got.error;
  // The child died before it answered: its temporaries are ours to remove.
  RemoveOwnTemporaries(request.output, child);
  std::string how;
  if (WIFSIGNALED(status)) {
    const int sig = WTERMSIG(status);
    how = "crashed with " + SignalName(sig) + (sig == SIGKILL ? " (perhaps for lack of memory)" : "") +
          (sig == SIGBUS ? " (the file may have been truncated while it was read)" : "");
  } else {
    how = "exited with code " + std::to_string(WEXITSTATUS(status)) +
          " before finishing (a sanitizer report or an exit in a library; see the messages on "
          "stderr)";
  }
  return Status(StatusCode::kInternal, request.input + ": the ingest child process (pid " +
                                           std::to_string(child) + ") " + how +
                                           "; its unfinished store is removed");
}

}  // namespace vox
