// vox.ingest's isolation: the ingest runs in a child process, as vox-ingest's
// runs under its supervisor (tools/common/supervisor.h), so that a .vdb that
// crashes OpenVDB's reader (or a sanitizer's exit) raises in Python instead of
// taking the interpreter down, and the child's temporary store is removed.
//
// The child is a fresh interpreter (posix_spawn of sys.executable, never a
// bare fork of a threaded process) that imports the module and calls
// RunIngestChild. Over two pipes it reports each progress point and waits
// for the parent's answer, so a Python progress callback runs at the same
// points, with the same effect, as in-process: the ingest waits for it, and
// a callback that raises (or a KeyboardInterrupt in the parent) stops the
// ingest there, its temporaries removed and the old store kept. SIGINT or
// SIGTERM to the child stops it the same way.
//
// Protocol, one line per message, child -> parent:
//   P DONE TOTAL VOXELS   a progress point; the child waits for one byte back:
//                         'c' continue, 's' stop
//   M TEXT                a phase message
//   R JSON                the ingest's statistics: it succeeded
//   E CODE JSON-STRING    the ingest's error Status
// A child that ends without R or E crashed.
//
// Thread safety: RunIngestChildProcess blocks its thread; call it from one
// thread per ingest.
#ifndef VOX_TOOLS_PYTHON_INGEST_PROCESS_H_
#define VOX_TOOLS_PYTHON_INGEST_PROCESS_H_

#include <atomic>
#include <string>
#include <vector>

#include "core/util/status.h"
#include "ingest/ingest.h"

namespace vox {

// What the parent asks the child: the ingest's input, output, the command
// line it records, and its flags (a flag, then its value when it takes one).
struct IngestChildRequest {
  std::string input, output, command_line;
  std::vector<std::string> flags;
};

// The parent: spawns `argv` (argv[0] is the program; the request is added
// after it) with `env`, relays progress to `sink` (may be null) and stops
// the child once `*cancel` or sink->Cancelled() is true. Returns the
// statistics' JSON; the ingest's own error; or Internal, naming `input` and
// the child's pid, when the child crashed (its temporaries beside `output`
// are then removed).
StatusOr<std::string> RunIngestChildProcess(const std::vector<std::string>& argv,
                                            const std::vector<std::string>& env,
                                            const IngestChildRequest& request,
                                            ProgressSink* sink,
                                            const std::atomic<bool>* cancel);

// The child: `args` are what RunIngestChildProcess added to argv. Runs the
// ingest, reports on the pipes and returns the process's exit code (0 once
// R or E was sent).
int RunIngestChild(const std::vector<std::string>& args);

}  // namespace vox

#endif  // VOX_TOOLS_PYTHON_INGEST_PROCESS_H_
