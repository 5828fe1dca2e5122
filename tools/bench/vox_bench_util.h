// Helpers of vox-bench (docs/accuracy.md): the run's context (command, machine, date),
// medians, Markdown/CSV tables, hand-written SVG plots, shelling out, and the
// cached test volumes (OpenVDB level sets made by vdb_tool, ingested into
// stores by the ingest library).
//
// Thread safety: thread-compatible; vox-bench calls these from its main thread.
#ifndef VOX_TOOLS_BENCH_VOX_BENCH_UTIL_H_
#define VOX_TOOLS_BENCH_VOX_BENCH_UTIL_H_

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "core/util/status.h"

namespace vox::bench {

// Where and how this run happens; printed above every table.
struct RunContext {
  std::string command;   // the command line that produced the results
  std::string machine;   // "2 cores (nproc), AMD EPYC"
  std::string date;      // UTC, ISO 8601
  std::string out_dir;   // docs/ or --out
  std::string work_dir;  // cached volumes
  bool quick = true;
  int threads = 2;
  int rounds = 5;  // repetitions of each timed measurement
  std::vector<int> grids, images;  // part 1's sizes (empty: the defaults)
};

// "Produced by `cmd` on MACHINE, DATE." (Markdown).
std::string Provenance(const RunContext& ctx);

double Median(std::vector<double> v);

// A table written both as Markdown and as CSV.
class Table {
 public:
  explicit Table(std::vector<std::string> columns) : columns_(std::move(columns)) {}
  void Add(std::vector<std::string> row) { rows_.push_back(std::move(row)); }
  std::string Markdown() const;
  std::string Csv() const;
  size_t size() const { return rows_.size(); }

 private:
  std::vector<std::string> columns_;
  std::vector<std::vector<std::string>> rows_;
};

// printf into a std::string.
std::string Fmt(const char* format, ...) __attribute__((format(printf, 1, 2)));

// One series of a plot: points with optional per-point labels.
struct Series {
  std::string name;
  std::vector<std::pair<double, double>> points;
  std::vector<std::string> labels;  // empty, or one per point
  bool line = true;                 // join the points
};

struct PlotSpec {
  std::string title, x_label, y_label;
  bool log_x = false, log_y = false;
  int width = 760, height = 480;
};

// An SVG document: axes with ticks and labels, one colour per series, a legend.
std::string SvgPlot(const PlotSpec& spec, const std::vector<Series>& series);

Status WriteFile(const std::string& path, const std::string& text);
bool FileExists(const std::string& path);
// Total bytes of the regular files under `dir`.
uint64_t DirectoryBytes(const std::string& dir);

// Runs `command` through /bin/sh, capturing stdout and stderr; error when it
// exits non-zero (the message ends with its last output).
StatusOr<std::string> RunCommand(const std::string& command);
// Shell-quotes one word.
std::string Quote(const std::string& s);

// A level-set sphere of radius 1 at the origin, `voxels` voxels across its
// diameter (half-width `band`), made by vdb_tool unless cached in work_dir.
StatusOr<std::string> EnsureSphereVdb(const RunContext& ctx, int voxels, double band);
// A platonic solid (faces 4, 6, 8, 12, 20), `voxels` across its bbox.
StatusOr<std::string> EnsurePlatonicVdb(const RunContext& ctx, int faces, int voxels);
// The store of `vdb` (ingested with "auto" levels, unless cached).
StatusOr<std::string> EnsureStore(const RunContext& ctx, const std::string& vdb);

// Greyscale / mask images and comparisons.
struct Image {
  int width = 0, height = 0;
  std::vector<float> rgb;    // 3 per pixel, row 0 at the top
  std::vector<uint8_t> mask; // 1 per pixel: something was hit
};
// Reads a binary PPM (P6, 8 bit) as written by vdb_render; mask = luminance > 0.5.
StatusOr<Image> ReadPpm(const std::string& path);
// Intersection over union of the masks (1 when both are empty).
double MaskIoU(const Image& a, const Image& b);
// Pixels whose masks differ.
uint64_t MaskDifferences(const Image& a, const Image& b);
// Mean absolute difference of luminance over pixels both masks cover.
double MeanAbsShadingDiff(const Image& a, const Image& b);
// Writes the mask difference as a PNG-free PPM: white both, red only a, blue only b.
Status WriteMaskDiffPpm(const std::string& path, const Image& a, const Image& b);

}  // namespace vox::bench

#endif  // VOX_TOOLS_BENCH_VOX_BENCH_UTIL_H_
