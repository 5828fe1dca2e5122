// vox-ingest's array inputs: a .npy file, or a raw file given --shape
// X,Y,Z and --dtype D (C order), with --voxel-size S and --origin X,Y,Z.
// The array becomes a fog volume in a temporary .vdb beside the output
// (ingest/array_ingest.h: element [i, j, k] is voxel (i, j, k) + origin,
// occupied above --threshold), which the ordinary ingest then reads.
#ifndef VOX_TOOLS_INGEST_ARRAY_INPUT_H_
#define VOX_TOOLS_INGEST_ARRAY_INPUT_H_

#include <string>
#include <vector>

namespace vox {

struct ArrayInput {
  bool wanted = false;       // the command line names an array input
  std::string error;         // non-empty: the command line or the array is refused
  // The exit code for `error`: 2 a bad command line, 1 an array file that
  // cannot be read or converted (as any input that fails: docs/usage.md).
  int exit_code = 2;
  std::vector<std::string> args;  // the command line for the ingest, the .vdb in the array's place
  std::string temp_vdb;      // to remove when the ingest is over
};

// Reads the array flags off the command line; with an array input, writes
// the temporary .vdb (a failure: error set, nothing left behind).
ArrayInput PrepareArrayInput(int argc, char** argv);

}  // namespace vox

#endif  // VOX_TOOLS_INGEST_ARRAY_INPUT_H_
