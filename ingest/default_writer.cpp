// vox::Ingest with the real StoreWriter. Kept apart from ingest.cpp so tests
// that substitute a writer do not need the storage library's writer.
#include "ingest/ingest.h"

namespace vox {

StatusOr<IngestStats> Ingest(const IngestOptions& options, ProgressSink* progress) {
  return IngestWithWriter(options, &StoreWriter::Create, progress);
}

}  // namespace vox
