// Publication of finished temporaries (core/util/file.h: CheckTarget,
// PublishAtomically): what a writer checked is all it may replace.
#include <fcntl.h>
#include <stdio.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <filesystem>
#include <string>

#include "core/util/file.h"

namespace vox {

StatusOr<CheckedTarget> CheckTarget(const std::string& target) {
  CheckedTarget c;
  struct stat st;
  if (lstat(target.c_str(), &st) != 0) {
    if (errno == ENOENT) return c;
    return ErrnoError("cannot examine", target, errno);
  }
  c.exists = true;
  c.directory = S_ISDIR(st.st_mode);
  c.device = uint64_t(st.st_dev);
  c.inode = uint64_t(st.st_ino);
  return c;
}

namespace {

std::atomic<bool> g_rename_flags_unsupported{false};

// renameat2 with `flags`, failing with EINVAL where tests pretend the file
// system has no such flags.
int Rename2(const std::string& from, const std::string& to, unsigned flags) {
  if (g_rename_flags_unsupported.load()) {
    errno = EINVAL;
    return -1;
  }
  return renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), flags);
}

bool FlagsUnsupported(int err) { return err == EINVAL || err == ENOSYS || err == ENOTSUP; }

Status AlreadyExists(const std::string& target, const std::string& what) {
  return InvalidArgumentError("'" + target + "' already exists; the " + what +
                              " was not published and nothing was replaced");
}

// Publishes `temp` at `target` where nothing may be replaced.
Status PublishNew(const std::string& temp, const std::string& target, const std::string& what) {
  if (Rename2(temp, target, RENAME_NOREPLACE) == 0) return OkStatus();
  if (errno == EEXIST) return AlreadyExists(target, what);
  if (!FlagsUnsupported(errno)) return ErrnoError("cannot rename '" + temp + "' to", target, errno);
  struct stat st;
  if (lstat(temp.c_str(), &st) != 0) return ErrnoError("cannot examine", temp, errno);
  if (!S_ISDIR(st.st_mode)) {  // link(2) never replaces
    if (link(temp.c_str(), target.c_str()) != 0)
      return errno == EEXIST ? AlreadyExists(target, what)
                             : ErrnoError("cannot link '" + temp + "' to", target, errno);
    unlink(temp.c_str());
    return OkStatus();
  }
  // A directory: claim the name with an empty placeholder, which rename(2)
  // replaces only while it is still empty.
  if (mkdir(target.c_str(), 0700) != 0)
    return errno == EEXIST ? AlreadyExists(target, what)
                           : ErrnoError("cannot create", target, errno);
  if (rename(temp.c_str(), target.c_str()) != 0) {
    const int err = errno;
    rmdir(target.c_str());  // only if still empty
    return ErrnoError("cannot rename '" + temp + "' to", target, err);
  }
  return OkStatus();
}

// Why what now lies at `old` (moved out of the target) is not what
// `checked` found there, or "".
std::string NotTheChecked(const std::string& old, const CheckedTarget& checked,
                          const ReplaceCheck& may_replace) {
  struct stat st;
  if (lstat(old.c_str(), &st) != 0) return "it cannot be examined";
  if (uint64_t(st.st_dev) != checked.device || uint64_t(st.st_ino) != checked.inode ||
      S_ISDIR(st.st_mode) != checked.directory)
    return std::string("it is not the ") + (checked.directory ? "directory" : "file") +
           " found there before";
  return may_replace ? may_replace(old) : "";
}

// Publishes `temp` at `target` in place of the `checked` one.
Status PublishReplacing(const std::string& temp, const std::string& target,
                        const std::string& what, const CheckedTarget& checked,
                        const ReplaceCheck& may_replace) {
  std::string old = temp;  // where the replaced one lies once moved out
  const bool exchanged = Rename2(temp, target, RENAME_EXCHANGE) == 0;
  if (!exchanged) {
    if (errno == ENOENT) return NotFoundError("'" + target + "' disappeared after it was checked");
    if (!FlagsUnsupported(errno)) return ErrnoError("cannot replace " + what, target, errno);
    old = temp + ".old";  // no atomic exchange here: move the old one aside
    if (rename(target.c_str(), old.c_str()) != 0)
      return ErrnoError("cannot move the old " + what + " aside", target, errno);
  }
  const std::string why = NotTheChecked(old, checked, may_replace);
  if (!why.empty()) {  // put it back as it was
    const bool back = exchanged ? Rename2(temp, target, RENAME_EXCHANGE) == 0
                                : rename(old.c_str(), target.c_str()) == 0;
    if (!back) {
      // Keep it out of reach of the caller's removal of `temp`.
      const std::string kept = target + ".kept-" + std::to_string(long(getpid()));
      rename(old.c_str(), kept.c_str());
      return IoError("'" + target + "' changed after it was checked (" + why +
                     ") and could not be put back: it is at '" + kept + "'");
    }
    return InvalidArgumentError("'" + target + "' changed after it was checked (" + why +
                                "); it was left as it is and the " + what + " was not published");
  }
  if (!exchanged && rename(temp.c_str(), target.c_str()) != 0) {
    const int err = errno;
    rename(old.c_str(), target.c_str());
    return ErrnoError("cannot rename '" + temp + "' to", target, err);
  }
  std::error_code ec;
  std::filesystem::remove_all(old, ec);
  if (ec)
    return IoError("cannot remove the replaced " + what + " at '" + old + "': " + ec.message());
  return OkStatus();
}

}  // namespace

void SetRenameFlagsUnsupportedForTesting(bool unsupported) {
  g_rename_flags_unsupported.store(unsupported);
}

Status PublishAtomically(const std::string& temp, const std::string& target,
                         const std::string& what, const CheckedTarget& checked,
                         const ReplaceCheck& may_replace) {
  VOX_RETURN_IF_ERROR(checked.exists ? PublishReplacing(temp, target, what, checked, may_replace)
                                     : PublishNew(temp, target, what));
  std::string dir, name;
  SplitPath(target, &dir, &name);
  return SyncDir(dir);
}

}  // namespace vox
