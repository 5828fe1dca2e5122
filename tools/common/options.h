// The options of vox-ingest, vox-render and vox-probe: each tool's option
// table (names, switch or value, help; tools/common/cli.h) and the function
// that applies one (flag, text value) pair (vox-probe's tracing is
// tools/common/prober.h). The tools' command lines and the Python module
// (tools/python: keyword zstd_level=3 is --zstd-level 3) both use them, so
// the two accept the same options and refuse bad ones with the same
// messages. Flags are spelled as on the command line ("--zstd-level", "-o");
// a switch's value is ignored.
//
// Thread safety: the tables are constants; the Apply and Check functions are pure.
#ifndef VOX_TOOLS_COMMON_OPTIONS_H_
#define VOX_TOOLS_COMMON_OPTIONS_H_

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "core/core.h"
#include "core/util/status.h"
#include "ingest/ingest.h"
#include "ingest/limits.h"
#include "render/job.h"
#include "render/lod.h"
#include "tools/common/cli.h"

namespace vox {

// vox-ingest: IngestOptions plus --quiet.
struct IngestCommand {
  IngestOptions options;
  bool quiet = false;
  std::string add_lod;  // --add-lod STORE: build the pyramid of an existing store instead
  IngestLimits limits;  // --max-voxels
};
// The options of vox-ingest (the same table as the Python module's ingest keywords).
OptionTable IngestOptionTable();
// InvalidArgumentError with vox-ingest's usage message for a bad value.
Status ApplyIngestFlag(IngestCommand* c, const std::string& flag, const std::string& value);
// The checks vox-ingest makes once all flags are read (threads, zstd level, levels).
Status CheckIngestCommand(const IngestCommand& c);

// vox-render: RenderJobOptions.
OptionTable RenderOptionTable();
Status ApplyRenderFlag(RenderJobOptions* o, const std::string& flag, const std::string& value);

// vox-probe.
struct ProbeOptions {
  std::string generate, store, split;  // a generated shape (--generate) or a store
  bool single_step = false, stats = false;
  int brick_level = -1;
  size_t cache_mb = 0;        // 0: from the memory budget
  uint64_t memory_bytes = 0;  // 0: detected
  int fixed = 0;              // 0: auto, else 64 or 128
  // --tracer: "render" (default) traces as vox-render does (AutoTracer<double>,
  // render/renderer.h's RenderTracer, with the store's occupied box);
  // "long-double" with a long-double set-up (DefaultTracer's arithmetic).
  std::string tracer = "render";
  double lod = 0.0;           // --lod F over the store's pyramid; 0: off
  double cone_rad = -1.0, cone_width = 0.0;  // the cone per ray: W + R t |dir| voxels at t
};
OptionTable ProbeOptionTable();
Status ApplyProbeFlag(ProbeOptions* o, const std::string& flag, const std::string& value);

}  // namespace vox

#endif  // VOX_TOOLS_COMMON_OPTIONS_H_
