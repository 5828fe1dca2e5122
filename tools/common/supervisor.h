// The supervisor of vox-ingest: the ingest runs in a child process (the tool
// re-executed with the same arguments, not a bare fork: the parent already
// has library threads, and a forked copy could inherit a lock one of them
// held and hang; it did, under ASan), so
// that a crash while reading a .vdb (OpenVDB's reader can crash on a corrupt
// file; a file truncated while it is read raises SIGBUS) or a sanitizer's
// exit ends with a message and a clean directory, not a dead tool and a
// temporary store left behind.
//
// The parent forwards SIGINT, SIGTERM and SIGHUP to the child; if the parent
// itself is SIGKILLed, the child is killed with it (PR_SET_PDEATHSIG) and the
// next run removes the temporary directory it leaves. In the child, SIGINT
// and SIGTERM are taken by one thread (StartSignalThread) that removes the
// child's temporary store and exits with 128 + the signal.
//
// Thread safety: process-wide (signal dispositions, fork); call from main.
#ifndef VOX_TOOLS_COMMON_SUPERVISOR_H_
#define VOX_TOOLS_COMMON_SUPERVISOR_H_

#include <functional>
#include <memory>
#include <string>

#include "ingest/ingest.h"

namespace vox {

// Runs `work` in a child process and returns its exit code: re-executes
// this program (/proc/self/exe) with `argv` and the environment variable
// VOX_INGEST_WORKER_FD, and the call in that child (the worker) runs `work`
// and exits. So everything before the call must do the same in both
// processes: parse `argv`, no output. A child that
// ends otherwise than by returning from `work` has its temporary store
// (`.NAME.tmp-PID-*` beside `output`, core/util/file.h) removed and is
// reported as a crash of the child process, naming `input`:
//   - killed by SIGKILL, SIGINT, SIGTERM or SIGHUP: "killed", exit 128 + N;
//   - killed by another signal (SIGSEGV, SIGBUS, SIGABRT...): a crash of
//     the ingest child process, with the signal's name, exit 1;
//   - exited without finishing `work` (a sanitizer report, an exit() in a
//     library): a crash with its exit code, exit 1.
// Errors `work` reports itself (OpenVDB's exceptions on a corrupt file
// become a Status) are its own messages. Without fork or exec, `work` runs
// here.
// `resume`: a resumable ingest (vox-ingest --resume), whose report says
// what its `.NAME.resume` keeps for the next run.
int RunSupervised(char** argv, const std::string& input, const std::string& output,
                  const std::function<int()>& work, bool resume = false);

// In the child: blocks SIGINT and SIGTERM in every thread created later and
// starts the thread that takes them (see above). `resume`: a resumable
// ingest, whose bricks written so far stay in `.NAME.resume` beside the
// output for the next run (the message says so).
void StartSignalThread(const std::string& output, bool resume = false);


// Test hooks of the child, read from the environment:
// VOX_INGEST_TEST_STALL stalls the first progress report (the temporary
// store exists), so tests can signal a real ingest mid-way;
// VOX_INGEST_TEST_CRASH=N raises signal N there instead (a crash while
// reading, at a known point); VOX_INGEST_TEST_EXIT=N calls _exit(N) there
// (as a sanitizer report does). Null when none is set; else a sink that
// forwards to `inner`.
std::unique_ptr<ProgressSink> MakeTestHookProgress(ProgressSink* inner);

}  // namespace vox

#endif  // VOX_TOOLS_COMMON_SUPERVISOR_H_
