// Fuzz target: .vdb ingest. The input is a .vdb file: it is written to a
// temporary directory and ingested into a store there, the way vox-ingest
// does it: in a forked child, so a crash in OpenVDB's reader (which vox
// cannot prevent) ends the child, not the fuzzer. The child checks what vox
// promises and reports by its exit code:
//   0  the ingest succeeded and the store opens, every brick decodes and
//      its brick count matches what the ingest reported
//   3  the ingest failed with a Status that names the input file and left
//      no store and no temporary behind
//   4  a broken promise: the message, store or leftovers say what
//   5  a sanitizer (ASan, UBSan) reported an error in the child: the
//      sanitizers' death callback, set in the child, exits with this code
//      whatever ASAN_OPTIONS' exitcode says (its default, 1, is what exit
//      codes alone could not tell apart)
// The parent aborts (libFuzzer keeps the input) on 4, on 5 and on any exit
// the child did not choose. What stays a rejection: a Status (3; OpenVDB's
// exceptions on a corrupt file become one), libFuzzer's out-of-memory exit
// (71, below) and a signal no sanitizer caught (the watchdog; in a build
// without ASan, a crash in OpenVDB's reader, as vox-ingest contains it).
// Under ASan a SEGV anywhere, OpenVDB's reader included, is a sanitizer
// report and fails: a finding to triage by its stack (vox must refuse such
// a file before OpenVDB reads it, as ingest/internal/vdb_topology.cpp does
// for oversized value chunks). Built with VOX_FUZZ_PLANTED_FAULT, the child
// reads one byte past a heap buffer after each ingest: the test
// fuzz_vdb_planted_fault (asan builds only) checks that the gate fails on
// it. Limits keep hostile but valid grids short:
// 256 MiB of ingest budget, at most 1e7 voxels from tiles, one thread, a
// 15 s alarm in the child; libFuzzer's -malloc_limit_mb applies in the child
// too: an allocation over it ends the child with libFuzzer's out-of-memory
// exit (71, its stack in the log). OpenVDB's reader allocates sizes it reads
// from the file (a metadata string of 1.9 GB, found here), which vox-ingest
// meets as a failed or killed child; vox's own allocations stay within the
// ingest budget, and VOX_FUZZ_VDB_IN_PROCESS=1 stops at any large one.
// VOX_FUZZ_VDB_IN_PROCESS=1 runs the ingest in the fuzzer's own process, so
// the sanitizers also stop at crashes in vox's side of the ingest (and in
// OpenVDB's: triage the result by the stack).
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <cstring>
#include <fstream>
#include <memory>
#include <string>

#include "ingest/ingest.h"
#include "ingest/limits.h"
#include "storage/store.h"

namespace {

namespace fs = std::filesystem;

constexpr int kOk = 0, kCleanError = 3, kBroken = 4, kSanitizerReport = 5;
constexpr int kLibFuzzerOutOfMemory = 71;  // libFuzzer's -malloc_limit_mb exit

// The sanitizers' runtime (sanitizer/common_interface_defs.h), absent from a
// build without them: then the weak reference is null.
extern "C" void __sanitizer_set_death_callback(void (*callback)(void)) __attribute__((weak));

#ifdef VOX_FUZZ_PLANTED_FAULT
// The planted fault: a heap read one byte past the end, which only a
// sanitizer sees (the volatile keeps the compiler from dropping it).
void PlantedOutOfBoundsRead(const std::string& text) {
  std::unique_ptr<char[]> copy(new char[text.size() + 1]);
  std::memcpy(copy.get(), text.c_str(), text.size() + 1);
  volatile char past = copy[text.size() + 1];
  (void)past;
}
#endif

int Broken(const std::string& what) {
  std::fprintf(stderr, "fuzz_vdb: %s\n", what.c_str());
  return kBroken;
}

// Ingests `input` into `output` and checks the outcome (the exit codes above).
int IngestAndCheck(const std::string& input, const std::string& output) {
  vox::IngestOptions o;
  o.input = input;
  o.output = output;
  o.threads = 1;
  o.memory_bytes = uint64_t(256) << 20;
  vox::IngestLimits limits;
  limits.max_tile_voxels = 10000000;
  auto stats = vox::Ingest(o, limits);
#ifdef VOX_FUZZ_PLANTED_FAULT
  PlantedOutOfBoundsRead(input);
#endif
  const fs::path dir = fs::path(output).parent_path();
  if (!stats.ok()) {
    const std::string msg = stats.status().ToString();
    if (msg.find(input) == std::string::npos) return Broken("error does not name the file: " + msg);
    for (const auto& e : fs::directory_iterator(dir))
      if (e.path() != fs::path(input))
        return Broken("left behind after '" + msg + "': " + e.path().string());
    return kCleanError;
  }
  vox::OpenOptions oo;
  oo.cache_bytes = size_t(64) << 20;
  auto store = vox::Store::Open(output, oo);
  if (!store.ok()) return Broken("the ingest's store does not open: " + store.status().ToString());
  const vox::StoreMeta& m = (*store)->meta();
  if (m.brick_count != stats->bricks)
    return Broken("store has " + std::to_string(m.brick_count) + " bricks, the ingest reported " +
                  std::to_string(stats->bricks));
  for (uint64_t b = 0; b < m.brick_count; ++b) {
    auto brick = (*store)->FetchBrick(uint32_t(b));
    if (!brick.ok()) return Broken("brick " + std::to_string(b) + ": " + brick.status().ToString());
  }
  return kOk;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static const fs::path base = [] {
    const char* t = std::getenv("TMPDIR");
    return fs::path(t && *t ? t : "/tmp") / ("vox-fuzz-vdb-" + std::to_string(getpid()));
  }();
  static const bool in_process = [] {
    const char* e = std::getenv("VOX_FUZZ_VDB_IN_PROCESS");
    return e != nullptr && e[0] == '1';
  }();
  std::error_code ec;
  fs::remove_all(base, ec);
  fs::create_directories(base);
  const std::string input = (base / "in.vdb").string(), output = (base / "store").string();
  std::ofstream(input, std::ios::binary)
      .write(reinterpret_cast<const char*>(data), std::streamsize(size));
  int code;
  if (in_process) {
    code = IngestAndCheck(input, output);
  } else {
    std::fflush(nullptr);
    const pid_t child = fork();
    if (child < 0) {
      std::perror("fuzz_vdb: fork");
      std::abort();
    }
    if (child == 0) {
      // An exception escaping Ingest is vox's bug (it promises a Status).
      std::set_terminate([] {
        std::fprintf(stderr, "fuzz_vdb: an exception escaped the ingest\n");
        _exit(kBroken);
      });
      // The watchdog: SIGALRM's default action ends the child (libFuzzer's
      // own -timeout handler, inherited, would exit with its code instead),
      // before the parent's libFuzzer -timeout (20 s in scripts/fuzz.sh).
      signal(SIGALRM, SIG_DFL);
      alarm(15);
      // A sanitizer's report ends the child with its own code, so the parent
      // cannot take it for a crash in OpenVDB.
      if (__sanitizer_set_death_callback != nullptr)
        __sanitizer_set_death_callback([] { _exit(kSanitizerReport); });
      const int c = IngestAndCheck(input, output);
      std::fflush(nullptr);
      _exit(c);
    }
    int status = 0;
    while (waitpid(child, &status, 0) < 0) {
    }
    // A signal no sanitizer caught (the watchdog, or OpenVDB's reader
    // crashing in a build without ASan) or an allocation over the malloc
    // cap: isolated, as in vox-ingest. Every other exit is the child's code.
    if (WIFSIGNALED(status)) {
      std::fprintf(stderr, "fuzz_vdb: the ingest's child ended by signal %d (contained)\n",
                   WTERMSIG(status));
      code = kOk;
    } else {
      code = WEXITSTATUS(status);
      if (code == kLibFuzzerOutOfMemory) code = kOk;
    }
  }
  fs::remove_all(base, ec);
  if (code == kSanitizerReport) {
    std::fprintf(stderr, "fuzz_vdb: a sanitizer reported an error in the ingest (see above)\n");
    std::abort();
  }
  if (code != kOk && code != kCleanError) {
    std::fprintf(stderr, "fuzz_vdb: the ingest broke a promise (exit %d, see above)\n", code);
    std::abort();
  }
  return 0;
}
