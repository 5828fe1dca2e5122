// Outputs never replace inputs: the paths a run reads and writes compared by
// identity before any work. An existing path is its file (device and inode,
// through symlinks: ./a.exr, a hard link and a link to it are one file); a
// path that does not exist yet is its directory's identity and its name, so
// two outputs spelled differently but naming one new file are caught too.
// Every tool (vox-render, vox-merge, vox-ingest, vox-gen) and the Python
// module run CheckDistinctPaths on all their inputs and outputs before
// reading anything.
//
// Thread safety: thread-compatible (stat calls only).
#ifndef VOX_CORE_UTIL_PATH_IDENTITY_H_
#define VOX_CORE_UTIL_PATH_IDENTITY_H_

#include <string>
#include <vector>

#include "core/util/status.h"

namespace vox {

// A path and what it is to the run, as messages name it ("-o", "camera",
// "store file").
struct NamedPath {
  std::string role;
  std::string path;
};

// The files of the store at `dir` a render reads: the regular files in it
// and in its pyramid's levels, lod/N/ (role "store file"; no deeper walk).
// Empty when `dir` is not a readable directory.
std::vector<NamedPath> StoreInputs(const std::string& dir);

// InvalidArgument, naming both paths, when an output is an input, when an
// output is a directory that holds an input (an output store replaced with
// --force), or when two outputs are one file. Inputs that do not exist and
// outputs that are devices or pipes (/dev/stdout, /dev/null) are not
// compared.
Status CheckDistinctPaths(const std::vector<NamedPath>& inputs,
                          const std::vector<NamedPath>& outputs);

// InvalidArgument unless `path` ends in `extension` (".exr", ".png"; any
// case): the format follows the name, so out.png never holds an EXR.
Status CheckExtension(const std::string& role, const std::string& path,
                      const std::string& extension);

}  // namespace vox

#endif  // VOX_CORE_UTIL_PATH_IDENTITY_H_
