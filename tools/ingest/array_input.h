// vox-ingest's array inputs: a .npy file, or a raw file given --shape
// X,Y,Z and --dtype D (C order), with --voxel-size S and --origin X,Y,Z.
// The file is mapped (not read) here; the ingest (ingest/array_ingest.h,
// IngestArray) then writes the store from it brick by brick: element
// [i, j, k] is voxel (i, j, k) + origin, occupied above --threshold. No
// temporary file is written.
#ifndef VOX_TOOLS_INGEST_ARRAY_INPUT_H_
#define VOX_TOOLS_INGEST_ARRAY_INPUT_H_

#include <memory>
#include <string>
#include <vector>

#include "ingest/array_ingest.h"

namespace vox {

struct ArrayInput {
  bool wanted = false;            // the command line names an array input
  std::string error;              // non-empty: a bad command line or array file
  // The exit code for `error`: 2 a bad command line, 1 an array file that
  // cannot be read (as any input that fails: docs/usage.md).
  int exit_code = 2;
  std::vector<std::string> args;  // the command line for the ingest, without the array flags
  std::unique_ptr<MappedArray> array;
  ArrayPlacement placement;       // its threshold: the ingest's --threshold
};

// Reads the array flags off the command line and, with an array input, maps
// the file and checks it against its header (or --shape and --dtype).
ArrayInput PrepareArrayInput(int argc, char** argv);

}  // namespace vox

#endif  // VOX_TOOLS_INGEST_ARRAY_INPUT_H_
