#include "tools/python/polled.h"

#include <pybind11/pybind11.h>

#include <chrono>
#include <condition_variable>
#include <exception>
#include <memory>
#include <mutex>
#include <thread>

namespace py = pybind11;

namespace vox {

void RunPolled(std::atomic<bool>* cancel, const std::function<void()>& work) {
  std::mutex mu;
  std::condition_variable cv;
  bool done = false;
  std::unique_ptr<py::error_already_set> interrupt;
  std::exception_ptr thrown;  // bad_alloc from the work: raised as MemoryError
  std::thread worker;
  {
    py::gil_scoped_release release;
    worker = std::thread([&] {
      try {
        work();
      } catch (...) {
        thrown = std::current_exception();
      }
      std::lock_guard<std::mutex> lock(mu);
      done = true;
      cv.notify_all();
    });
  }
  for (;;) {
    {
      py::gil_scoped_release release;
      std::unique_lock<std::mutex> lock(mu);
      cv.wait_for(lock, std::chrono::milliseconds(50), [&] { return done; });
      if (done) break;
    }
    if (!interrupt && PyErr_CheckSignals() != 0) {
      interrupt = std::make_unique<py::error_already_set>();  // fetched: the error is kept
      cancel->store(true);
    }
  }
  {
    py::gil_scoped_release release;
    worker.join();
  }
  if (interrupt) {
    interrupt->restore();
    throw py::error_already_set();
  }
  if (thrown) std::rethrow_exception(thrown);
}

}  // namespace vox
