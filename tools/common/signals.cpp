#include "tools/common/signals.h"

#include <pthread.h>
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include "core/util/file.h"

namespace vox {

std::string SignalName(int sig) {
  const char* abbrev = sigabbrev_np(sig);
  const char* text = strsignal(sig);
  return (abbrev ? "SIG" + std::string(abbrev) : "signal " + std::to_string(sig)) + " (" +
         (text ? text : "unknown") + ")";
}

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

void RemoveOwnTemporaries(const std::vector<std::string>& outputs, pid_t pid) {
  namespace fs = std::filesystem;
  // Directory -> the temporaries' name prefixes of its outputs.
  std::map<std::string, std::set<std::string>> prefixes;
  const std::string tag = ".tmp-" + std::to_string(pid) + "-";
  for (std::string target : outputs) {
    if (target.empty()) continue;
    while (target.size() > 1 && target.back() == '/') target.pop_back();
    fs::path tp(target), parent = tp.parent_path();
    if (parent.empty()) parent = ".";
    prefixes[parent.string()].insert("." + tp.filename().string() + tag);
  }
  for (const auto& [dir, names] : prefixes) {
    for (int attempt = 0; attempt < 3; ++attempt) {  // writers may still be adding files
      std::error_code ec;
      bool left = false;
      for (const auto& e : fs::directory_iterator(dir, ec)) {
        const std::string name = e.path().filename().string();
        const size_t at = name.find(tag);
        if (at == std::string::npos || !names.count(name.substr(0, at + tag.size()))) continue;
        std::error_code rec;
        fs::remove_all(e.path(), rec);
        left = left || fs::exists(e.path(), rec);
      }
      if (!left) break;
    }
  }
}

namespace {
std::atomic<bool> g_signal_taken{false};
// The outputs whose temporaries the signal thread removes. Never destroyed:
// the detached signal thread may read them while the process exits (a
// signal during exit's static destructors found a freed vector and crashed).
struct SignalOutputs {
  std::mutex mutex;
  std::vector<std::string> paths;
};
SignalOutputs& Outputs() {
  static SignalOutputs* outputs = new SignalOutputs;
  return *outputs;
}
}  // namespace

void AddSignalOutputs(const std::vector<std::string>& outputs) {
  SignalOutputs& o = Outputs();
  std::lock_guard<std::mutex> lock(o.mutex);
  o.paths.insert(o.paths.end(), outputs.begin(), outputs.end());
}

int ToolExitCode(int code) {
  if (!g_signal_taken.load()) return code;
  for (;;) pause();  // the signal thread ends the process
}

void StartOutputSignalThread(const std::string& tool, const std::vector<std::string>& outputs) {
  AddSignalOutputs(outputs);
  sigset_t set;
  sigemptyset(&set);
  for (int sig : {SIGINT, SIGTERM, SIGHUP}) sigaddset(&set, sig);
  pthread_sigmask(SIG_BLOCK, &set, nullptr);  // inherited by every thread created later
  std::thread([set, tool] {
    int sig = 0;
    if (sigwait(&set, &sig) != 0) return;
    g_signal_taken = true;
    // Held until _Exit: no temporary is created, no group half-published, after
    // the removal below.
    std::unique_lock<std::mutex> hold(TemporaryMutex());
    std::fprintf(stderr, "\n%s: %s: removing the unfinished outputs and exiting\n", tool.c_str(),
                 sig == SIGINT ? "interrupted (SIGINT)"
                 : sig == SIGHUP ? "hung up (SIGHUP)" : "terminated (SIGTERM)");
    std::vector<std::string> outputs;
    {
      SignalOutputs& o = Outputs();
      std::lock_guard<std::mutex> lock(o.mutex);
      outputs = o.paths;
    }
    RemoveOwnTemporaries(outputs, getpid());
    std::_Exit(128 + sig);
  }).detach();
}

}  // namespace vox
