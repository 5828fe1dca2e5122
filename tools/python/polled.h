// RunPolled: a long call of the Python module run on its own thread, the
// GIL released, while the calling (main) thread answers Python's signals, so
// that Ctrl-C stops vox.render, vox.ingest and vox.probe within a moment.
//
// Thread safety: call with the GIL held, from the thread Python calls in.
#ifndef VOX_TOOLS_PYTHON_POLLED_H_
#define VOX_TOOLS_PYTHON_POLLED_H_

#include <atomic>
#include <functional>

namespace vox {

// Runs `work` on its own thread, the GIL released, while this thread checks
// for signals (PyErr_CheckSignals, which acts only on Python's main thread)
// every 50 ms. A signal handler's exception (KeyboardInterrupt) sets
// *cancel, which the work polls (between tiles, at each brick, at each ray) to stop and
// remove its temporaries; once the work has returned, the exception is
// raised. Ctrl-C thus stops vox.render, vox.ingest and vox.probe within a moment, and
// no output is published after it.
void RunPolled(std::atomic<bool>* cancel, const std::function<void()>& work);

}  // namespace vox

#endif  // VOX_TOOLS_PYTHON_POLLED_H_
