// Helpers of the kill and fault tests: starting a tool in its own process
// group (so one kill(-pid) reaches its children too), and listing the
// temporaries (`.NAME.tmp-...`) a directory holds.
//
// Thread safety: thread-safe (posix_spawn); the tools' own effects are not.
#ifndef VOX_TESTS_COMMON_SPAWN_H_
#define VOX_TESTS_COMMON_SPAWN_H_

#include <fcntl.h>
#include <spawn.h>
#include <unistd.h>

#include <filesystem>
#include <string>
#include <vector>

namespace vox::testing {

// Starts args[0] (a path) with `args` in a new process group, its standard
// output and error to /dev/null. Returns its pid, or -1.
inline pid_t SpawnInGroup(const std::vector<std::string>& args) {
  std::vector<char*> argv;
  for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  posix_spawnattr_t attr;
  posix_spawnattr_init(&attr);
  posix_spawnattr_setpgroup(&attr, 0);
  posix_spawnattr_setflags(&attr, POSIX_SPAWN_SETPGROUP);
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&fa, 2, "/dev/null", O_WRONLY, 0);
  pid_t pid = -1;
  if (posix_spawn(&pid, argv[0], &fa, &attr, argv.data(), environ) != 0) pid = -1;
  posix_spawn_file_actions_destroy(&fa);
  posix_spawnattr_destroy(&attr);
  return pid;
}

// The names of the entries of `dir` that are temporaries (hold ".tmp-").
inline std::vector<std::string> TempEntries(const std::string& dir) {
  std::vector<std::string> v;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    if (e.path().filename().string().find(".tmp-") != std::string::npos)
      v.push_back(e.path().filename().string());
  return v;
}

}  // namespace vox::testing

#endif  // VOX_TESTS_COMMON_SPAWN_H_
