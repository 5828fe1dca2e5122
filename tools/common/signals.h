// Signals of the tools that write outputs in-process (vox-render, vox-merge,
// vox-ingest --add-lod) and the temporaries they leave: SIGINT, SIGTERM and
// SIGHUP stop the tool, remove its temporaries and keep earlier outputs, as
// vox-ingest's supervisor does for its child (supervisor.h).
//
// Thread safety: process-wide (signal masks); call from main before any
// thread is created.
#ifndef VOX_TOOLS_COMMON_SIGNALS_H_
#define VOX_TOOLS_COMMON_SIGNALS_H_

#include <sys/types.h>

#include <string>
#include <vector>

namespace vox {

// A signal's name and description: "SIGSEGV (Segmentation fault)".
std::string SignalName(int sig);

// Removes the temporaries `.NAME.tmp-PID-*` (files or directories) of
// process `pid` beside `output` (core/util/file.h).
void RemoveOwnTemporaries(const std::string& output, pid_t pid);

// The same for many outputs at once: one listing of each directory.
void RemoveOwnTemporaries(const std::vector<std::string>& outputs, pid_t pid);

// vox-render, vox-merge and vox-ingest --add-lod, which run in-process: blocks
// SIGINT, SIGTERM and SIGHUP in every thread created later and starts the
// thread that takes them. It waits for a publication under way
// (OutputGroup::Commit) to end, removes this process's temporaries of every
// path in `outputs` (`.NAME.tmp-PID-*` beside it), says so on stderr as
// `tool` and exits with 128 + the signal: earlier outputs stay as they were.
void StartOutputSignalThread(const std::string& tool, const std::vector<std::string>& outputs);

// More outputs whose temporaries the signal thread removes (a frame
// sequence's, known once its cameras are read). Thread-safe.
void AddSignalOutputs(const std::vector<std::string>& outputs);

// The tool's exit code `code`, unless the signal thread has taken a signal:
// then the work may have failed only because its temporaries were removed
// under it, and this waits for the thread to exit the process with 128 + the
// signal instead.
int ToolExitCode(int code);

}  // namespace vox

#endif  // VOX_TOOLS_COMMON_SIGNALS_H_
