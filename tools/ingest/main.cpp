// vox-ingest: reads an OpenVDB grid and writes a vox store.
//   vox-ingest data.vdb store/ [--grid NAME] [--levels N1+N2|auto] [--isovalue F]
//              [--threshold F] [--color GRID] [--zstd-level L] [--normal-bits B] [--threads N]
//              [--memory-mb N] [--max-voxels N] [--no-lod] [--force] [--quiet]
//   vox-ingest --add-lod store/ [--force] [--quiet]
// Exit codes: 0 done, 1 the ingest failed (or crashed: see below), 2 bad
// command line, 128+N killed by signal N (SIGINT, SIGTERM, SIGKILL: the
// temporary store directory is removed).
//
// The ingest runs in a forked child. OpenVDB's reader can crash on a corrupt
// .vdb (a segfault in its decompression or topology code), and a file
// truncated while it is read raises SIGBUS; the parent sees the child die by
// a signal, reports it naming the file, removes the child's temporary store
// and exits 1. The parent forwards SIGINT and SIGTERM to the child; if the
// parent itself is SIGKILLed, the child is killed with it (PR_SET_PDEATHSIG)
// and the next run removes the temporary directory it leaves.
#include <pthread.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <new>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "ingest/ingest.h"
#include "ingest/limits.h"
#include "storage/lod.h"
#include "storage/memory_budget.h"
#include "tools/common/flags.h"
#include "tools/common/options.h"

namespace {

constexpr char kUsage[] =
    "usage: vox-ingest data.vdb store/ [--grid NAME] [--levels N1+N2|auto] [--isovalue F]\n"
    "                  [--threshold F] [--color GRID] [--zstd-level L] [--normal-bits B]\n"
    "                  [--threads N] [--memory-mb N] [--max-voxels N] [--no-lod] [--force] [--quiet]\n"
    "       vox-ingest --add-lod store/ [--zstd-level L] [--force] [--quiet]\n"
    "  --grid NAME      the grid to ingest (default: the first float or double grid)\n"
    "  --levels         auto (32^3 bricks) or N1+N2: N1 resident levels above bricks of\n"
    "                   N2 levels (2^N2 voxels per axis); each at most 20, N1+N2 at most 40\n"
    "  --isovalue F     level sets: a voxel is occupied when active and value <= F (default 0)\n"
    "  --threshold F    fog volumes: occupied when active and density > F (default 0)\n"
    "  --color GRID     a vec3s/vec3d grid sampled as each voxel's RGB colour\n"
    "  --zstd-level L   brick compression level, 1..22 (default 3)\n"
    "  --normal-bits B  level sets: bits per octahedral normal component, 8..16 (default 16,\n"
    "                   max error 0.004 degrees; 12: 0.06 degrees and a smaller store)\n"
    "  --threads N      worker threads (default: all cores)\n"
    "  --memory-mb N    memory the ingest may hold, MiB or with a unit (512, 2G; default: the\n"
    "                   process's memory cgroup limit or available memory)\n"
    "  --max-voxels N   the most voxels active tiles may expand to (default 1e10); a grid\n"
    "                   whose occupied tiles cover more is refused\n"
    "  --no-lod         skip the level-of-detail pyramid (store/lod/, for vox-render --lod;\n"
    "                   written by default)\n"
    "  --add-lod STORE  add the level-of-detail pyramid to an existing store (--force\n"
    "                   replaces one it has)\n"
    "  --force          replace an existing store\n"
    "  --quiet          no progress output\n";

int UsageError(const std::string& message) {
  std::fprintf(stderr, "vox-ingest: %s\n%s", message.c_str(), kUsage);
  return 2;
}

// SIGINT and SIGTERM (a Slurm time-out) are blocked in every thread and
// taken by one thread with sigwait, which is an ordinary thread: it removes
// this process's temporary store directory `.NAME.tmp-PID-*` beside the
// output (storage/FORMAT.md, "Writing") and exits with 128 + the signal.
void RemoveOwnTemporaries(const std::string& output, pid_t pid) {
  namespace fs = std::filesystem;
  std::string target = output;
  while (target.size() > 1 && target.back() == '/') target.pop_back();
  fs::path tp(target), parent = tp.parent_path();
  if (parent.empty()) parent = ".";
  const std::string prefix =
      "." + tp.filename().string() + ".tmp-" + std::to_string(pid) + "-";
  for (int attempt = 0; attempt < 3; ++attempt) {  // writers may still be adding files
    std::error_code ec;
    bool left = false;
    for (const auto& e : fs::directory_iterator(parent, ec)) {
      if (e.path().filename().string().compare(0, prefix.size(), prefix) != 0) continue;
      std::error_code rec;
      fs::remove_all(e.path(), rec);
      left = left || fs::exists(e.path(), rec);
    }
    if (!left) return;
  }
}

void StartSignalThread(const std::string& output) {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);  // inherited by every thread created later
  std::thread([set, output] {
    int sig = 0;
    if (sigwait(&set, &sig) != 0) return;
    std::fprintf(stderr, "\nvox-ingest: %s: removing the unfinished store and exiting\n",
                 sig == SIGINT ? "interrupted (SIGINT)" : "terminated (SIGTERM)");
    RemoveOwnTemporaries(output, getpid());
    std::_Exit(128 + sig);
  }).detach();
}

// Test hooks: with VOX_INGEST_TEST_STALL set, the first progress report
// stalls the ingest (the temporary store exists), so tests can signal a
// real ingest mid-way; with VOX_INGEST_TEST_CRASH=N it raises signal N
// there instead (a crash while reading, at a known point).
class StallingProgress : public vox::ProgressSink {
 public:
  explicit StallingProgress(vox::ProgressSink* inner, int crash_signal)
      : inner_(inner), crash_signal_(crash_signal) {}
  void Message(std::string_view line) override {
    if (inner_) inner_->Message(line);
  }
  void Progress(uint64_t done, uint64_t total, uint64_t voxels) override {
    if (crash_signal_ > 0) {
      signal(crash_signal_, SIG_DFL);
      raise(crash_signal_);
    }
    std::fprintf(stderr, "vox-ingest: test stall\n");
    for (;;) pause();
    if (inner_) inner_->Progress(done, total, voxels);
  }
  void Done() override {
    if (inner_) inner_->Done();
  }

 private:
  vox::ProgressSink* inner_;
  int crash_signal_ = 0;
};

volatile sig_atomic_t g_child = 0;

extern "C" void ForwardToChild(int sig) {
  if (g_child > 0) kill(pid_t(g_child), sig);
}

// Runs `ingest` in a forked child and returns its exit code; a child killed
// by a signal is reported (naming `input`) and its temporary store removed.
template <typename F>
int RunInChild(const std::string& input, const std::string& output, F ingest) {
  std::fflush(nullptr);
  const pid_t parent = getpid();
  const pid_t child = fork();
  if (child < 0) return ingest();  // cannot fork: run unprotected
  if (child == 0) {
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(128 + SIGKILL);  // the parent died before prctl
    const int code = ingest();
    std::fflush(nullptr);
    _exit(code);
  }
  g_child = child;
  struct sigaction sa;
  std::memset(&sa, 0, sizeof sa);
  sa.sa_handler = ForwardToChild;
  sigemptyset(&sa.sa_mask);
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) sigaction(sig, &sa, nullptr);
  int status = 0;
  while (waitpid(child, &status, 0) < 0) {
    if (errno != EINTR) {
      std::perror("vox-ingest: waitpid");
      return 1;
    }
  }
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  const int sig = WIFSIGNALED(status) ? WTERMSIG(status) : SIGKILL;
  RemoveOwnTemporaries(output, child);
  if (sig == SIGKILL || sig == SIGINT || sig == SIGTERM || sig == SIGHUP) {
    std::fprintf(stderr, "vox-ingest: the ingest was killed by signal %d (%s)%s; its unfinished "
                 "store is removed\n", sig, strsignal(sig),
                 sig == SIGKILL ? ", perhaps for lack of memory" : "");
    return 128 + sig;
  }
  std::fprintf(stderr,
               "vox-ingest: %s: OpenVDB crashed reading the grid (signal %d, %s): the file is "
               "corrupt or truncated\n",
               input.c_str(), sig, strsignal(sig));
  return 1;
}

}  // namespace

static int IngestAndReport(const vox::IngestOptions& o, const vox::IngestLimits& limits,
                           bool quiet);

static int RunTool(int argc, char** argv) {
  vox::IngestCommand command;
  vox::IngestOptions& o = command.options;
  std::vector<std::string> positional;
  vox::FlagReader flags(argc, argv);
  o.command_line = flags.CommandLine("vox-ingest");
  while (flags.Next()) {
    const std::string a = flags.arg();
    if (flags.IsHelp()) {
      std::fputs(kUsage, stdout);
      return 0;
    } else if (flags.IsFlag()) {
      const vox::FlagArity arity = vox::IngestFlagArity(a);
      if (arity == vox::FlagArity::kUnknown) return UsageError("unknown option " + a);
      std::optional<std::string> v;
      if (arity == vox::FlagArity::kValue && !(v = flags.Value()))
        return UsageError(a + " needs a value");
      vox::Status s = vox::ApplyIngestFlag(&command, a, v.value_or(""));
      if (!s.ok()) return UsageError(s.message());
    } else {
      positional.push_back(a);
    }
  }
  const bool quiet = command.quiet;
  const std::string& add_lod = command.add_lod;
  if (!add_lod.empty()) {
    if (!positional.empty())
      return UsageError("--add-lod takes one store and no other input or output");
    if (!o.lod) return UsageError("--add-lod and --no-lod exclude each other");
    if (o.zstd_level < 1 || o.zstd_level > 22) return UsageError("--zstd-level must be in 1..22");
    vox::LodBuildOptions lo;
    lo.zstd_level = o.zstd_level;
    lo.normal_bits = o.normal_bits;
    lo.force = o.force;
    auto st = vox::BuildLod(add_lod, lo);
    if (!st.ok()) {
      std::fprintf(stderr, "vox-ingest: --add-lod: %s\n", st.status().ToString().c_str());
      return 1;
    }
    if (!quiet) {
      uint64_t bricks = 0;
      for (uint64_t b : st->bricks) bricks += b;
      std::fprintf(stderr,
                   "added %s/lod: %d levels, %llu bricks, from %llu base bricks in %.2f s\n",
                   add_lod.c_str(), st->levels, (unsigned long long)bricks,
                   (unsigned long long)st->base_bricks_read, st->seconds);
    }
    return 0;
  }
  if (positional.size() != 2)
    return UsageError("expected an input .vdb file and an output store directory, got " +
                      std::to_string(positional.size()) + " arguments");
  o.input = positional[0];
  o.output = positional[1];
  if (vox::Status s = vox::CheckIngestCommand(command); !s.ok()) return UsageError(s.message());

  return RunInChild(o.input, o.output, [&] { return IngestAndReport(o, command.limits, quiet); });
}

static int IngestAndReport(const vox::IngestOptions& o, const vox::IngestLimits& limits,
                           bool quiet) {
  StartSignalThread(o.output);
  std::unique_ptr<vox::ProgressSink> progress;
  if (!quiet) progress = vox::MakeStderrProgress(isatty(STDERR_FILENO) != 0);
  std::unique_ptr<vox::ProgressSink> stall;
  const char* crash = std::getenv("VOX_INGEST_TEST_CRASH");
  if (std::getenv("VOX_INGEST_TEST_STALL") != nullptr || crash != nullptr)
    stall = std::make_unique<StallingProgress>(progress.get(), crash ? std::atoi(crash) : 0);
  auto stats = vox::Ingest(o, limits, stall ? stall.get() : progress.get());
  if (!stats.ok()) {
    std::fprintf(stderr, "vox-ingest: %s\n", stats.status().ToString().c_str());
    return 1;
  }
  if (!quiet) {
    const vox::IngestStats& s = *stats;
    double rate = s.seconds_total > 0 ? double(s.active_voxels) / s.seconds_total : 0;
    std::fprintf(stderr,
                 "wrote %s: %llu occupied voxels in %llu bricks (levels %d+%d), %llu active "
                 "voxels read in %.2f s (%.1f M active voxels/s, %d threads; open %.2f s, bbox "
                 "%.2f s, bricks %.2f s, finish %.2f s; level of detail: %d levels, %.2f s)\n",
                 o.output.c_str(), (unsigned long long)s.occupied_voxels,
                 (unsigned long long)s.bricks, s.meta.brick_level,
                 s.meta.levels - s.meta.brick_level, (unsigned long long)s.active_voxels,
                 s.seconds_total, rate / 1e6, s.threads, s.seconds_open, s.seconds_bbox,
                 s.seconds_bricks, s.seconds_finish, s.lod_levels, s.seconds_lod);
  }
  return 0;
}

// Allocation failures anywhere (an image, a brick, a table sized from input)
// end with a clear message and exit 1, never an abort.
int main(int argc, char** argv) {
  try {
    return RunTool(argc, argv);
  } catch (const std::bad_alloc&) {
    fprintf(stderr, "vox-ingest: out of memory (std::bad_alloc); try smaller sizes or budgets\n");
    return 1;
  }
}
