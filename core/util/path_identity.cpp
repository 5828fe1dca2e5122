#include "core/util/path_identity.h"

#include <sys/stat.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <optional>

#include "core/util/file.h"

namespace vox {
namespace {

// A file's identity: an existing file's device and inode (name empty), or a
// new file's directory's device and inode and its name.
struct Identity {
  dev_t dev = 0;
  ino_t ino = 0;
  std::string name;
  bool operator==(const Identity& o) const {
    return dev == o.dev && ino == o.ino && name == o.name;
  }
};

std::optional<Identity> ExistingIdentity(const std::string& path) {
  struct stat st;
  if (stat(path.c_str(), &st) != 0) return std::nullopt;
  return Identity{st.st_dev, st.st_ino, ""};
}

// The identity `path` has or will have once written; nullopt when neither
// it nor its directory exists.
std::optional<Identity> OutputIdentity(const std::string& path) {
  if (auto id = ExistingIdentity(path)) return id;
  std::string trimmed = path;
  while (trimmed.size() > 1 && trimmed.back() == '/') trimmed.pop_back();
  std::string dir, name;
  SplitPath(trimmed, &dir, &name);
  auto parent = ExistingIdentity(dir);
  if (!parent) return std::nullopt;
  parent->name = name;
  return parent;
}

bool IsSpecial(const std::string& path) {
  struct stat st;
  return stat(path.c_str(), &st) == 0 && (S_ISCHR(st.st_mode) || S_ISFIFO(st.st_mode));
}

// The identities of the directories above `path` (its real path's
// ancestors, up to the root).
std::vector<Identity> AncestorIdentities(const std::string& path) {
  namespace fs = std::filesystem;
  std::vector<Identity> out;
  std::error_code ec;
  fs::path p = fs::canonical(path, ec);
  if (ec) return out;
  while (p.has_parent_path() && p.parent_path() != p) {
    p = p.parent_path();
    if (auto id = ExistingIdentity(p.string())) out.push_back(*id);
  }
  return out;
}

std::string Described(const NamedPath& p) { return p.role + " " + p.path; }

}  // namespace

std::vector<NamedPath> StoreInputs(const std::string& dir) {
  namespace fs = std::filesystem;
  // The store's own files and its pyramid's (lod/N/*), not a deep walk: a
  // wrong STORE such as / must not be listed whole before Open refuses it.
  std::vector<NamedPath> out;
  auto add_files = [&out](const fs::path& d, std::vector<fs::path>* subdirs) {
    std::error_code ec;
    for (fs::directory_iterator it(d, ec), end; !ec && it != end; it.increment(ec)) {
      std::error_code sec;
      if (it->is_regular_file(sec))
        out.push_back({"store file", it->path().string()});
      else if (subdirs != nullptr && it->is_directory(sec))
        subdirs->push_back(it->path());
    }
  };
  add_files(dir, nullptr);
  std::vector<fs::path> levels;
  add_files(fs::path(dir) / "lod", &levels);
  for (const fs::path& level : levels) add_files(level, nullptr);
  return out;
}

Status CheckDistinctPaths(const std::vector<NamedPath>& inputs,
                          const std::vector<NamedPath>& outputs) {
  std::vector<std::pair<Identity, const NamedPath*>> seen;
  for (const NamedPath& out : outputs) {
    if (out.path.empty() || IsSpecial(out.path)) continue;
    const std::optional<Identity> id = OutputIdentity(out.path);
    if (!id) continue;  // its directory is missing: CheckOutputPath says so
    for (const auto& [other_id, other] : seen)
      if (*id == other_id)
        return InvalidArgumentError(Described(out) + " and " + Described(*other) +
                                    " are the same file; give each output its own path");
    seen.push_back({*id, &out});
    for (const NamedPath& in : inputs) {
      if (in.path.empty()) continue;
      const std::optional<Identity> in_id = ExistingIdentity(in.path);
      if (!in_id) continue;
      if (*in_id == *id)
        return InvalidArgumentError(Described(out) + " is the " + Described(in) +
                                    "; writing it would destroy that input");
      for (const Identity& above : AncestorIdentities(in.path))
        if (above == *id)
          return InvalidArgumentError(Described(out) + " holds the " + Described(in) +
                                      "; replacing it would destroy that input");
    }
  }
  return OkStatus();
}

Status CheckExtension(const std::string& role, const std::string& path,
                      const std::string& extension) {
  auto lower = [](std::string s) {
    std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
    return s;
  };
  const bool matches = path.size() > extension.size() &&
                       lower(path.substr(path.size() - extension.size())) == extension;
  if (!matches)
    return InvalidArgumentError(role + " " + path + ": the file name must end in " + extension +
                                " (the format follows the name)");
  return OkStatus();
}

}  // namespace vox
