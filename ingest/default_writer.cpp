// The ingest's defaults: vox::Ingest with the real StoreWriter, and the
// stderr progress display of vox-ingest. Kept apart from ingest.cpp so tests
// that substitute a writer do not need the storage library's writer.
#include <string>

#include "core/util/progress.h"
#include "ingest/ingest.h"
#include "ingest/limits.h"

namespace vox {

StatusOr<IngestStats> Ingest(const IngestOptions& options, ProgressSink* progress) {
  return IngestWithWriter(options, &StoreWriter::Create, progress);
}

StatusOr<IngestStats> Ingest(const IngestOptions& options, const IngestLimits& limits,
                             ProgressSink* progress) {
  return IngestWithWriter(options, limits, &StoreWriter::Create, progress);
}

namespace {

// "[####    ]  42% 420/1000 bricks, 123456 voxels, 1m20s left" on a terminal
// (the time left once a second has passed), the same
// text without the bar every 10% otherwise.
class StderrProgress : public ProgressSink {
 public:
  explicit StderrProgress(bool terminal)
      : display_(terminal ? ProgressMode::kBar : ProgressMode::kPlain, stderr,
                 ProgressStyle{.bar_width = 40,
                               .bar_empty = ' ',
                               .clear_to_line_end = false,
                               .plain_first_step = false}) {}

  void Message(std::string_view line) override { display_.Message(line); }

  void Progress(uint64_t done, uint64_t total, uint64_t voxels) override {
    if (total == 0) return;
    done_ = done;
    total_ = total;
    voxels_ = voxels;
    display_.Update(done, total, [this](double now) { return Text(now); });
  }

  void Done() override {
    if (total_ > 0) display_.Finish(done_, total_, [this](double now) { return Text(now); });
  }

 private:
  // `now`: seconds since the display started; the time left is the
  // elapsed time scaled by the bricks still to write.
  std::string Text(double now) const {
    char buf[160];
    std::snprintf(buf, sizeof buf, "%3d%% %llu/%llu bricks, %llu voxels",
                  int(done_ * 100 / total_), (unsigned long long)done_,
                  (unsigned long long)total_, (unsigned long long)voxels_);
    std::string text = buf;
    if (done_ > 0 && done_ < total_ && now >= 1.0)
      text += ", " + vox::Progress::Duration(now * double(total_ - done_) / double(done_)) + " left";
    return text;
  }

  vox::Progress display_;
  uint64_t done_ = 0, total_ = 0, voxels_ = 0;
};

}  // namespace

std::unique_ptr<ProgressSink> MakeStderrProgress(bool terminal) {
  return std::make_unique<StderrProgress>(terminal);
}

}  // namespace vox
