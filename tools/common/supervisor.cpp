#include "tools/common/supervisor.h"

#include <fcntl.h>
#include <pthread.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "storage/store_writer.h"
#include "tools/common/signals.h"

namespace vox {
namespace {

class TestHookProgress : public ProgressSink {
 public:
  TestHookProgress(ProgressSink* inner, int crash_signal, int exit_code)
      : inner_(inner), crash_signal_(crash_signal), exit_code_(exit_code) {}
  void Message(std::string_view line) override {
    if (inner_) inner_->Message(line);
  }
  void Progress(uint64_t done, uint64_t total, uint64_t voxels) override {
    if (crash_signal_ > 0) {
      signal(crash_signal_, SIG_DFL);
      raise(crash_signal_);
    }
    if (exit_code_ >= 0) _exit(exit_code_);
    std::fprintf(stderr, "vox-ingest: test stall\n");
    for (;;) pause();
    if (inner_) inner_->Progress(done, total, voxels);
  }
  void Done() override {
    if (inner_) inner_->Done();
  }

 private:
  ProgressSink* inner_;
  int crash_signal_ = 0;
  int exit_code_ = -1;
};

volatile sig_atomic_t g_child = 0;

extern "C" void ForwardToChild(int sig) {
  if (g_child > 0) kill(pid_t(g_child), sig);
}

constexpr char kWorkerEnv[] = "VOX_INGEST_WORKER_FD";

// The worker (the re-executed tool): runs `work` and tells the parent it
// returned (one byte on `done_fd`) before exiting with its code.
[[noreturn]] void RunWorker(int done_fd, const std::function<int()>& work) {
  const int code = work();
  std::fflush(nullptr);
  const char done = 1;
  while (write(done_fd, &done, 1) < 0 && errno == EINTR) {
  }
  _exit(code);
}

// The environment of the worker: this process's, with kWorkerEnv=done_fd.
// Built before fork: between fork and exec only async-signal-safe calls are
// made (the parent has threads: OpenVDB's logging library starts a pool when
// it is loaded, and a plain fork could inherit a lock one of them held).
struct WorkerEnv {
  std::vector<std::string> strings;
  std::vector<char*> pointers;
  explicit WorkerEnv(int done_fd) {
    for (char** e = environ; *e; ++e)
      if (std::strncmp(*e, kWorkerEnv, sizeof kWorkerEnv - 1) != 0) strings.emplace_back(*e);
    strings.push_back(std::string(kWorkerEnv) + "=" + std::to_string(done_fd));
    for (std::string& s : strings) pointers.push_back(s.data());
    pointers.push_back(nullptr);
  }
};

// What an ended resumable ingest keeps for the next run, when its
// directory beside the output holds its journal ("" when it does not).
std::string KeptForResume(const std::string& output, bool resume) {
  std::error_code ec;
  if (!resume || !std::filesystem::exists(ResumeJournal(output), ec)) return "";
  return "the bricks written so far are kept in '" + ResumeDirectory(output) +
         "': run it again with --resume to continue";
}

// How the child ended, as the parent reports it and the tool's exit code.
int ReportChild(const std::string& input, const std::string& output, pid_t child, int status,
                bool finished, bool resume) {
  if (WIFEXITED(status) && (finished || WEXITSTATUS(status) == 128 + SIGINT ||
                            WEXITSTATUS(status) == 128 + SIGTERM))
    return WEXITSTATUS(status);
  RemoveOwnTemporaries(output, child);
  const std::string kept_for_resume = KeptForResume(output, resume);
  const std::string kept = kept_for_resume.empty() ? "its unfinished store is removed"
                                                   : "no store written; " + kept_for_resume;
  if (WIFEXITED(status)) {
    std::fprintf(stderr,
                 "vox-ingest: %s: the ingest child process (pid %d) crashed: it exited with "
                 "code %d before finishing (a sanitizer report or an exit in a library; see "
                 "the messages above); %s\n",
                 input.c_str(), int(child), WEXITSTATUS(status), kept.c_str());
    return 1;
  }
  const int sig = WIFSIGNALED(status) ? WTERMSIG(status) : SIGKILL;
  if (sig == SIGKILL || sig == SIGINT || sig == SIGTERM || sig == SIGHUP) {
    std::fprintf(stderr, "vox-ingest: the ingest was killed by signal %d (%s)%s; %s\n", sig,
                 strsignal(sig), sig == SIGKILL ? ", perhaps for lack of memory" : "",
                 kept.c_str());
    return 128 + sig;
  }
  std::fprintf(stderr,
               "vox-ingest: %s: the ingest child process (pid %d) crashed with %s while "
               "reading the grid%s; %s\n",
               input.c_str(), int(child), SignalName(sig).c_str(),
               sig == SIGBUS ? " (the file may have been truncated while it was read)" : "",
               kept.c_str());
  return 1;
}

}  // namespace

int RunSupervised(char** argv, const std::string& input, const std::string& output,
                  const std::function<int()>& work, bool resume) {
  if (const char* fd = std::getenv(kWorkerEnv)) {  // this is the worker
    const int done_fd = std::atoi(fd);
    unsetenv(kWorkerEnv);
    RunWorker(done_fd, work);
  }
  std::fflush(nullptr);
  // done: the worker's "work returned" byte. exec_failed: closed by a
  // successful exec (O_CLOEXEC), else carries the exec's errno.
  int done[2], exec_failed[2];
  if (pipe2(done, O_CLOEXEC) != 0) return work();  // cannot watch a child: run unprotected
  if (pipe2(exec_failed, O_CLOEXEC) != 0) {
    close(done[0]);
    close(done[1]);
    return work();
  }
  WorkerEnv env(done[1]);
  const pid_t parent = getpid();
  const pid_t child = fork();
  if (child < 0) {  // cannot fork: run unprotected
    for (int fd : {done[0], done[1], exec_failed[0], exec_failed[1]}) close(fd);
    return work();
  }
  if (child == 0) {  // async-signal-safe calls only, up to the exec
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(128 + SIGKILL);  // the parent died before prctl
    fcntl(done[1], F_SETFD, 0);                     // the worker inherits it
    execve("/proc/self/exe", argv, env.pointers.data());
    const int err = errno;
    while (write(exec_failed[1], &err, sizeof err) < 0 && errno == EINTR) {
    }
    _exit(127);
  }
  close(done[1]);
  close(exec_failed[1]);
  g_child = child;
  struct sigaction sa;
  std::memset(&sa, 0, sizeof sa);
  sa.sa_handler = ForwardToChild;
  sigemptyset(&sa.sa_mask);
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) sigaction(sig, &sa, nullptr);
  int exec_errno = 0;
  ssize_t n;
  while ((n = read(exec_failed[0], &exec_errno, sizeof exec_errno)) < 0 && errno == EINTR) {
  }
  close(exec_failed[0]);
  int status = 0;
  while (waitpid(child, &status, 0) < 0) {
    if (errno != EINTR) {
      std::perror("vox-ingest: waitpid");
      close(done[0]);
      return 1;
    }
  }
  if (n == sizeof exec_errno) {  // the worker never started: nothing of it to clean
    close(done[0]);
    std::fprintf(stderr,
                 "vox-ingest: cannot start the ingest child process (/proc/self/exe): %s; "
                 "running the ingest unprotected\n",
                 std::strerror(exec_errno));
    for (int sig : {SIGINT, SIGTERM, SIGHUP}) signal(sig, SIG_DFL);
    return work();
  }
  char byte = 0;
  while ((n = read(done[0], &byte, 1)) < 0 && errno == EINTR) {
  }
  close(done[0]);
  return ReportChild(input, output, child, status, n == 1, resume);
}

void StartSignalThread(const std::string& output, bool resume) {
  sigset_t set;
  sigemptyset(&set);
  sigaddset(&set, SIGINT);
  sigaddset(&set, SIGTERM);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);  // inherited by every thread created later
  // What an interrupted ingest keeps: the store is built in a temporary
  // directory and replaces what is at the output (--force, --add-lod) only
  // when complete, so the output is as it was before the run.
  std::error_code ec;
  const bool existed = std::filesystem::exists(output, ec);
  const std::string written = existed ? "no store written: '" + output + "' is as it was before"
                                      : "no store written at '" + output + "'";
  std::thread([set, output, written, existed, resume] {
    int sig = 0;
    if (sigwait(&set, &sig) != 0) return;
    // A resumable ingest's bricks stay in its directory (once it holds a journal).
    const std::string for_resume = KeptForResume(output, resume);
    const std::string what = !for_resume.empty() ? written + "; " + for_resume
                             : existed           ? written
                                                 : written + ", nothing left behind";
    std::fprintf(stderr, "\nvox-ingest: %s; %s\n",
                 sig == SIGINT ? "interrupted (SIGINT)" : "terminated (SIGTERM)", what.c_str());
    RemoveOwnTemporaries(output, getpid());
    std::_Exit(128 + sig);
  }).detach();
}

std::unique_ptr<ProgressSink> MakeTestHookProgress(ProgressSink* inner) {
  const char* crash = std::getenv("VOX_INGEST_TEST_CRASH");
  const char* exit_code = std::getenv("VOX_INGEST_TEST_EXIT");
  if (std::getenv("VOX_INGEST_TEST_STALL") == nullptr && crash == nullptr && exit_code == nullptr)
    return nullptr;
  return std::make_unique<TestHookProgress>(inner, crash ? std::atoi(crash) : 0,
                                            exit_code ? std::atoi(exit_code) : -1);
}

}  // namespace vox
