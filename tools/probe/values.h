// vox-probe's value modes (storage/sample.h): `--at X Y Z` prints a store's
// values at points, `--slice AXIS INDEX -o OUT.exr` writes a plane of voxels
// as an EXR.
#ifndef VOX_TOOLS_PROBE_VALUES_H_
#define VOX_TOOLS_PROBE_VALUES_H_

namespace vox {

// True when the command line asks for a value mode (--at or --slice).
bool WantsValues(int argc, char** argv);
// Runs it; returns the exit code (0 done, 1 failed, 2 bad command line).
int RunValues(int argc, char** argv);

}  // namespace vox

#endif  // VOX_TOOLS_PROBE_VALUES_H_
