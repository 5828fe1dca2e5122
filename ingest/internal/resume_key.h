// The key a resumable ingest (IngestOptions::resume) gives its writer
// (WriteOptions::resume_key): the input's identity (its path, size and
// modification time) and the options that change the bricks, so that a run
// resumes only the bricks of the same input ingested the same way. The
// writer adds the store's metadata (placement, class, thresholds, transform).
// Private to ingest.
//
// Thread safety: stateless; thread-safe.
#ifndef VOX_INGEST_INTERNAL_RESUME_KEY_H_
#define VOX_INGEST_INTERNAL_RESUME_KEY_H_

#include <sys/stat.h>

#include <string>

#include "ingest/ingest.h"

namespace vox::ingest_internal {

// Empty without options.resume. `extra`: what else defines the input (an
// array's dtype, shape and order).
inline std::string ResumeKeyOf(const IngestOptions& o, const std::string& extra) {
  if (!o.resume) return {};
  std::string k = "input " + o.input;
  struct stat st;
  if (::stat(o.input.c_str(), &st) == 0)
    k += " " + std::to_string(st.st_size) + " bytes, modified " +
         std::to_string(st.st_mtim.tv_sec) + "." + std::to_string(st.st_mtim.tv_nsec);
  k += "\ngrid " + o.grid_name + " color " + o.color_grid + " temperature " + o.temperature_grid;
  k += "\nlevels " + o.levels + " lod " + std::to_string(o.lod) + "\n" + extra;
  return k;
}

}  // namespace vox::ingest_internal

#endif  // VOX_INGEST_INTERNAL_RESUME_KEY_H_
