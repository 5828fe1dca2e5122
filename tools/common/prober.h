// vox::Prober: vox-probe's store opening and ray tracing, for vox-probe and
// the Python module's vox.probe, from the options tools/common/options.h
// parses.
//
// Thread safety: a Prober is immutable once opened and Trace is
// thread-compatible (one thread at a time: vox-probe traces on one thread).
#ifndef VOX_TOOLS_COMMON_PROBER_H_
#define VOX_TOOLS_COMMON_PROBER_H_

#include <memory>
#include <optional>

#include "core/core.h"
#include "core/util/status.h"
#include "render/lod.h"
#include "tools/common/options.h"

namespace vox {
class Store;
}  // namespace vox

namespace vox {

// The options' checks that need no volume: flags that exclude or need each
// other, and values out of range. vox-probe runs them first, as a bad
// command line (exit 2); Open and OpenOn run them too.
Status CheckProbeOptions(const ProbeOptions& options);

// vox-probe's volume (a store under the memory budget, or a generated shape)
// and tracer (split, fixed-point word), ready to trace index-space rays.
class Prober {
 public:
  // Errors carry, as their message, the line vox-probe prints.
  static StatusOr<std::unique_ptr<Prober>> Open(const ProbeOptions& options);
  // A Prober over `store`, already open and outliving it (vox-view's, shared
  // with its renders: its brick cache and budget), tracing as Open's would
  // over the same store; `options`' store, memory and cache fields are unused.
  static StatusOr<std::unique_ptr<Prober>> OpenOn(Store* store, const ProbeOptions& options);
  ~Prober();
  // The first hit of an index-space ray (voxel in index coordinates, t along
  // the ray); nullopt on a miss. Errors: the ray is invalid (ValidateRay).
  StatusOr<std::optional<Hit>> Trace(const Ray& index_ray, TraceCounters* counters) const;
  // With --lod: the ray's first stop over the pyramid (render/lod.h). A stop
  // at a coarse cell of level *level > 0 has voxel = the cell's first voxel
  // (index coordinates); rays the cone keeps at level 0 answer as Trace.
  bool lod() const;
  StatusOr<std::optional<Hit>> TraceLod(const Ray& index_ray, TraceCounters* counters,
                                        LodCounters* lod_counters, int* level) const;

 private:
  struct Impl;
  explicit Prober(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace vox

#endif  // VOX_TOOLS_COMMON_PROBER_H_
