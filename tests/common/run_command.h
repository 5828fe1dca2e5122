// vox::testing::RunCommand: runs a shell command line (sh -c) with its
// standard error folded into its standard output, for tests that drive the
// tools end to end. Returns the exit code (128 + N when signal N ended it,
// as a shell reports it) and everything the command printed.
//
// Thread safety: thread-safe (popen); the command's own effects are not.
#ifndef VOX_TESTS_COMMON_RUN_COMMAND_H_
#define VOX_TESTS_COMMON_RUN_COMMAND_H_

#include <sys/wait.h>

#include <cstdio>
#include <string>

namespace vox::testing {

struct CommandResult {
  int code = -1;  // -1: the command could not be started
  std::string output;
};

inline CommandResult RunCommand(const std::string& cmd) {
  CommandResult r;
  FILE* p = popen((cmd + " 2>&1").c_str(), "r");
  if (p == nullptr) return r;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, p)) > 0) r.output.append(buf, n);
  const int status = pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  return r;
}

}  // namespace vox::testing

#endif  // VOX_TESTS_COMMON_RUN_COMMAND_H_
