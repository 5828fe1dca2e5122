// vox core: fixed-point numbers, the packed-register octree traversal, the
// paper's integer DDA and its two-step transition, and an in-memory octree.
// Owns no I/O: bricks arrive through the BrickSource interface that storage
// implements. Also the plumbing every layer shares: Status (core/util/status.h),
// Stopwatch (core/util/stopwatch.h) and the progress display (core/util/progress.h,
// which writes to a stream its caller gives). Depends on nothing else in vox.
#ifndef VOX_CORE_CORE_H_
#define VOX_CORE_CORE_H_

#include "core/fixed_point.h"
#include "core/octree.h"
#include "core/ray.h"
#include "core/util/status.h"
#include "core/tracer.h"

#endif  // VOX_CORE_CORE_H_
