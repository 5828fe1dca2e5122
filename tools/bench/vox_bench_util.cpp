// Helpers of vox-bench: see vox_bench_util.h.
#include "tools/bench/vox_bench_util.h"

#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "ingest/ingest.h"

namespace vox::bench {

std::string Fmt(const char* format, ...) {
  va_list ap;
  va_start(ap, format);
  char buf[1024];
  int n = vsnprintf(buf, sizeof buf, format, ap);
  va_end(ap);
  if (n < int(sizeof buf)) return std::string(buf, std::max(n, 0));
  std::string s(size_t(n) + 1, '\0');
  va_start(ap, format);
  vsnprintf(s.data(), s.size(), format, ap);
  va_end(ap);
  s.resize(size_t(n));
  return s;
}

std::string Provenance(const RunContext& ctx) {
  return "Produced by `" + ctx.command + "` on " + ctx.machine + ", " + ctx.date + " (" +
         std::to_string(ctx.threads) + " render threads; times are medians of " +
         std::to_string(ctx.rounds) +
         " rounds, every configuration of a table timed once per round, side by side).\n";
}

double Median(std::vector<double> v) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

std::string Table::Markdown() const {
  std::string s = "|";
  for (const auto& c : columns_) s += " " + c + " |";
  s += "\n|";
  for (size_t i = 0; i < columns_.size(); ++i) s += " --- |";
  s += "\n";
  for (const auto& r : rows_) {
    s += "|";
    for (const auto& c : r) s += " " + c + " |";
    s += "\n";
  }
  return s;
}

static std::string CsvField(const std::string& f) {
  std::string plain;
  for (char c : f)
    if (c != '*' && c != '`') plain += c;  // Markdown emphasis is not data
  if (plain.find_first_of(",\"\n") == std::string::npos) return plain;
  std::string q = "\"";
  for (char c : plain) {
    if (c == '"') q += '"';
    q += c;
  }
  return q + "\"";
}

std::string Table::Csv() const {
  std::string s;
  for (size_t i = 0; i < columns_.size(); ++i) s += (i ? "," : "") + CsvField(columns_[i]);
  s += "\n";
  for (const auto& r : rows_) {
    for (size_t i = 0; i < r.size(); ++i) s += (i ? "," : "") + CsvField(r[i]);
    s += "\n";
  }
  return s;
}

// ------------------------------------------------------------------ SVG

namespace {

std::string Esc(const std::string& s) {
  std::string o;
  for (char c : s) {
    if (c == '<') o += "&lt;";
    else if (c == '>') o += "&gt;";
    else if (c == '&') o += "&amp;";
    else o += c;
  }
  return o;
}

struct Axis {
  double lo = 0, hi = 1;
  bool log = false;
  std::vector<double> ticks;

  double Map(double v) const {  // -> [0, 1]
    if (log) return (std::log10(v) - std::log10(lo)) / (std::log10(hi) - std::log10(lo));
    return (v - lo) / (hi - lo);
  }
};

Axis MakeAxis(std::vector<double> values, bool log) {
  Axis a;
  a.log = log;
  if (log) values.erase(std::remove_if(values.begin(), values.end(), [](double v) { return !(v > 0); }),
                        values.end());
  if (values.empty()) values = {log ? 1.0 : 0.0, log ? 10.0 : 1.0};
  double lo = *std::min_element(values.begin(), values.end());
  double hi = *std::max_element(values.begin(), values.end());
  if (log) {
    double l0 = std::floor(std::log10(lo)), l1 = std::ceil(std::log10(hi));
    if (l1 <= l0) l1 = l0 + 1;
    a.lo = std::pow(10.0, l0);
    a.hi = std::pow(10.0, l1);
    const bool few = l1 - l0 <= 2;
    for (double e = l0; e <= l1; ++e)
      for (double m : few ? std::vector<double>{1, 2, 5} : std::vector<double>{1}) {
        double t = m * std::pow(10.0, e);
        if (t <= a.hi * 1.0001) a.ticks.push_back(t);
      }
    return a;
  }
  if (hi == lo) {
    hi = lo + 1;
    lo = lo - 1;
  }
  double span = hi - lo;
  double step = std::pow(10.0, std::floor(std::log10(span / 5)));
  for (double m : {1.0, 2.0, 5.0, 10.0})
    if (span / (step * m) <= 6) {
      step *= m;
      break;
    }
  a.lo = std::floor(lo / step) * step;
  a.hi = std::ceil(hi / step) * step;
  if (lo >= 0 && a.lo < 0) a.lo = 0;
  for (double t = a.lo; t <= a.hi + step * 1e-6; t += step) a.ticks.push_back(t);
  return a;
}

std::string TickText(double v) {
  if (v == 0) return "0";
  double av = std::fabs(v);
  if (av >= 1e5 || av < 1e-3) return Fmt("%.0e", v);
  if (av >= 10 || v == std::round(v)) return Fmt("%g", v);
  return Fmt("%.3g", v);
}

const char* kColors[] = {"#1f77b4", "#d62728", "#2ca02c", "#ff7f0e", "#9467bd",
                         "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf"};

}  // namespace

std::string SvgPlot(const PlotSpec& spec, const std::vector<Series>& series) {
  std::vector<double> xs, ys;
  for (const auto& s : series)
    for (auto [x, y] : s.points) {
      if (std::isfinite(x)) xs.push_back(x);
      if (std::isfinite(y)) ys.push_back(y);
    }
  Axis ax = MakeAxis(xs, spec.log_x), ay = MakeAxis(ys, spec.log_y);
  const double W = spec.width, H = spec.height;
  const double left = 80, right = 200, top = 40, bottom = 60;
  const double pw = W - left - right, ph = H - top - bottom;
  auto X = [&](double v) { return left + ax.Map(v) * pw; };
  auto Y = [&](double v) { return top + (1 - ay.Map(v)) * ph; };
  std::ostringstream o;
  o << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << W << "\" height=\"" << H
    << "\" viewBox=\"0 0 " << W << " " << H << "\" font-family=\"sans-serif\" font-size=\"12\">\n";
  o << "<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n";
  o << "<text x=\"" << left + pw / 2 << "\" y=\"22\" text-anchor=\"middle\" font-size=\"15\">"
    << Esc(spec.title) << "</text>\n";
  // Grid and ticks.
  for (double t : ax.ticks) {
    double x = X(t);
    o << "<line x1=\"" << x << "\" y1=\"" << top << "\" x2=\"" << x << "\" y2=\"" << top + ph
      << "\" stroke=\"#e6e6e6\"/>\n";
    o << "<text x=\"" << x << "\" y=\"" << top + ph + 16 << "\" text-anchor=\"middle\">"
      << TickText(t) << "</text>\n";
  }
  for (double t : ay.ticks) {
    double y = Y(t);
    o << "<line x1=\"" << left << "\" y1=\"" << y << "\" x2=\"" << left + pw << "\" y2=\"" << y
      << "\" stroke=\"#e6e6e6\"/>\n";
    o << "<text x=\"" << left - 6 << "\" y=\"" << y + 4 << "\" text-anchor=\"end\">" << TickText(t)
      << "</text>\n";
  }
  o << "<rect x=\"" << left << "\" y=\"" << top << "\" width=\"" << pw << "\" height=\"" << ph
    << "\" fill=\"none\" stroke=\"black\"/>\n";
  o << "<text x=\"" << left + pw / 2 << "\" y=\"" << H - 18 << "\" text-anchor=\"middle\">"
    << Esc(spec.x_label) << (spec.log_x ? " (log scale)" : "") << "</text>\n";
  o << "<text transform=\"translate(18," << top + ph / 2
    << ") rotate(-90)\" text-anchor=\"middle\">" << Esc(spec.y_label)
    << (spec.log_y ? " (log scale)" : "") << "</text>\n";
  // Data. Point labels are moved up or down until they overlap no other.
  struct Box {
    double x0, y0, x1, y1;
  };
  std::vector<Box> placed;
  auto place = [&](double x, double y, const std::string& text) {
    const double w = 5.6 * double(text.size()), h = 11;
    for (int k = 0; k < 40; ++k) {
      double dy = (k % 2 ? 1 : -1) * 12.0 * double((k + 1) / 2);
      double ty = y - 5 + dy;
      Box b{x + 5, ty - h + 2, x + 5 + w, ty + 2};
      bool clash = false;
      for (const Box& p : placed)
        if (b.x0 < p.x1 && p.x0 < b.x1 && b.y0 < p.y1 && p.y0 < b.y1) clash = true;
      if (!clash || k == 39) {
        placed.push_back(b);
        return ty;
      }
    }
    return y - 5;
  };
  for (size_t si = 0; si < series.size(); ++si) {
    const Series& s = series[si];
    const char* col = kColors[si % 10];
    std::vector<std::pair<double, double>> pts;
    for (auto [x, y] : s.points) {
      bool ok = std::isfinite(x) && std::isfinite(y) && (!spec.log_x || x > 0) && (!spec.log_y || y > 0);
      pts.push_back(ok ? std::make_pair(X(x), Y(y)) : std::make_pair(std::nan(""), 0.0));
    }
    if (s.line) {
      o << "<polyline fill=\"none\" stroke=\"" << col << "\" stroke-width=\"1.8\" points=\"";
      for (auto [x, y] : pts)
        if (std::isfinite(x)) o << x << "," << y << " ";
      o << "\"/>\n";
    }
    for (size_t i = 0; i < pts.size(); ++i) {
      auto [x, y] = pts[i];
      if (!std::isfinite(x)) continue;
      o << "<circle cx=\"" << x << "\" cy=\"" << y << "\" r=\"3.5\" fill=\"" << col << "\"/>\n";
      if (i < s.labels.size() && !s.labels[i].empty()) {
        double ty = place(x, y, s.labels[i]);
        if (std::fabs(ty - (y - 5)) > 1)  // a leader line to a moved label
          o << "<line x1=\"" << x << "\" y1=\"" << y << "\" x2=\"" << x + 5 << "\" y2=\"" << ty - 3
            << "\" stroke=\"" << col << "\" stroke-width=\"0.6\"/>\n";
        o << "<text x=\"" << x + 5 << "\" y=\"" << ty << "\" font-size=\"10\" fill=\"" << col << "\">"
          << Esc(s.labels[i]) << "</text>\n";
      }
    }
    double ly = top + 14 + 18 * double(si);
    o << "<line x1=\"" << left + pw + 12 << "\" y1=\"" << ly - 4 << "\" x2=\"" << left + pw + 32
      << "\" y2=\"" << ly - 4 << "\" stroke=\"" << col << "\" stroke-width=\"2\"/>\n";
    o << "<circle cx=\"" << left + pw + 22 << "\" cy=\"" << ly - 4 << "\" r=\"3.5\" fill=\"" << col
      << "\"/>\n";
    o << "<text x=\"" << left + pw + 38 << "\" y=\"" << ly << "\">" << Esc(s.name) << "</text>\n";
  }
  o << "</svg>\n";
  return o.str();
}

// ------------------------------------------------------------------ files

Status WriteFile(const std::string& path, const std::string& text) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  if (!f) return IoError("cannot create " + path);
  f << text;
  f.close();
  if (!f) return IoError("cannot write " + path);
  return OkStatus();
}

bool FileExists(const std::string& path) {
  struct stat st;
  return stat(path.c_str(), &st) == 0;
}

uint64_t DirectoryBytes(const std::string& dir) {
  uint64_t total = 0;
  std::error_code ec;
  for (auto it = std::filesystem::recursive_directory_iterator(dir, ec);
       !ec && it != std::filesystem::recursive_directory_iterator(); it.increment(ec))
    if (it->is_regular_file(ec)) total += it->file_size(ec);
  return total;
}

std::string Quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) {
    if (c == '\'') q += "'\\''";
    else q += c;
  }
  return q + "'";
}

StatusOr<std::string> RunCommand(const std::string& command) {
  FILE* p = popen(("(" + command + "\n) 2>&1").c_str(), "r");
  if (p == nullptr) return IoError("cannot run: " + command);
  std::string out;
  char buf[4096];
  size_t n;
  while ((n = fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, n);
  int rc = pclose(p);
  if (rc != 0) {
    std::string tail = out.size() > 600 ? out.substr(out.size() - 600) : out;
    return InternalError("command failed (status " + std::to_string(rc) + "): " + command + "\n" + tail);
  }
  return out;
}

// ------------------------------------------------------------------ volumes

StatusOr<std::string> EnsureSphereVdb(const RunContext& ctx, int voxels, double band) {
  std::string path = ctx.work_dir + "/sphere" + std::to_string(voxels) +
                     (band == 3 ? std::string() : Fmt("_w%g", band)) + ".vdb";
  if (FileExists(path)) return path;
  std::string tmp = path + ".tmp.vdb";
  // vdb_tool's "voxel" wins over "dim": 2 / voxels gives `voxels` voxels across.
  VOX_RETURN_IF_ERROR(RunCommand(Fmt("vdb_tool -sphere voxel=%.17g radius=1 center=0,0,0 width=%g -write ",
                                     2.0 / voxels, band) +
                                 Quote(tmp))
                          .status());
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) return IoError("cannot rename " + tmp + ": " + ec.message());
  return path;
}

StatusOr<std::string> EnsurePlatonicVdb(const RunContext& ctx, int faces, int voxels) {
  std::string path = ctx.work_dir + "/platonic" + std::to_string(faces) + "_" +
                     std::to_string(voxels) + ".vdb";
  if (FileExists(path)) return path;
  std::string tmp = path + ".tmp.vdb";
  VOX_RETURN_IF_ERROR(
      RunCommand(Fmt("vdb_tool -platonic faces=%d scale=1 dim=%d voxel=%.17g -write ", faces, voxels,
                     // scale 1: the solid's bbox is about 1..1.7 units; voxel sets the count.
                     faces == 6 ? 1.0 / voxels : 2.0 / voxels) +
                 Quote(tmp))
          .status());
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) return IoError("cannot rename " + tmp + ": " + ec.message());
  return path;
}

StatusOr<std::string> EnsureStore(const RunContext& ctx, const std::string& vdb) {
  std::string store = vdb.substr(0, vdb.size() - 4) + ".store";
  if (FileExists(store + "/top.bin") || FileExists(store)) {
    std::error_code ec;
    if (std::filesystem::is_directory(store, ec) && !std::filesystem::is_empty(store, ec)) return store;
  }
  IngestOptions o;
  o.input = vdb;
  o.output = store;
  o.threads = ctx.threads;
  o.force = true;
  o.command_line = "vox-bench";
  VOX_RETURN_IF_ERROR(Ingest(o).status());
  return store;
}

// ------------------------------------------------------------------ images

StatusOr<Image> ReadPpm(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) return NotFoundError("cannot open " + path);
  std::string magic;
  int w = 0, h = 0, maxv = 0;
  f >> magic >> w >> h >> maxv;
  f.get();
  if (magic != "P6" || w <= 0 || h <= 0 || maxv != 255)
    return InvalidArgumentError(path + ": not an 8-bit binary PPM");
  std::vector<unsigned char> px(size_t(w) * h * 3);
  f.read(reinterpret_cast<char*>(px.data()), std::streamsize(px.size()));
  if (!f) return InvalidArgumentError(path + ": truncated PPM");
  Image im;
  im.width = w;
  im.height = h;
  im.rgb.resize(px.size());
  im.mask.resize(size_t(w) * h);
  for (size_t i = 0; i < im.mask.size(); ++i) {
    float lum = 0;
    for (int c = 0; c < 3; ++c) {
      im.rgb[3 * i + c] = float(px[3 * i + c]) / 255.0f;
      lum += im.rgb[3 * i + c] / 3;
    }
    im.mask[i] = lum > 0.5f;
  }
  return im;
}

double MaskIoU(const Image& a, const Image& b) {
  uint64_t inter = 0, uni = 0;
  size_t n = std::min(a.mask.size(), b.mask.size());
  for (size_t i = 0; i < n; ++i) {
    inter += a.mask[i] && b.mask[i];
    uni += a.mask[i] || b.mask[i];
  }
  return uni ? double(inter) / double(uni) : 1.0;
}

uint64_t MaskDifferences(const Image& a, const Image& b) {
  uint64_t d = 0;
  size_t n = std::min(a.mask.size(), b.mask.size());
  for (size_t i = 0; i < n; ++i) d += a.mask[i] != b.mask[i];
  return d;
}

double MeanAbsShadingDiff(const Image& a, const Image& b) {
  double sum = 0;
  uint64_t n = 0;
  size_t m = std::min(a.mask.size(), b.mask.size());
  for (size_t i = 0; i < m; ++i) {
    if (!a.mask[i] || !b.mask[i]) continue;
    double la = (a.rgb[3 * i] + a.rgb[3 * i + 1] + a.rgb[3 * i + 2]) / 3;
    double lb = (b.rgb[3 * i] + b.rgb[3 * i + 1] + b.rgb[3 * i + 2]) / 3;
    sum += std::fabs(la - lb);
    ++n;
  }
  return n ? sum / double(n) : 0.0;
}

Status WriteMaskDiffPpm(const std::string& path, const Image& a, const Image& b) {
  std::string s = "P6\n" + std::to_string(a.width) + " " + std::to_string(a.height) + "\n255\n";
  for (size_t i = 0; i < a.mask.size(); ++i) {
    bool x = a.mask[i], y = i < b.mask.size() && b.mask[i];
    unsigned char px[3] = {0, 0, 0};
    if (x && y) px[0] = px[1] = px[2] = 200;
    else if (x) px[0] = 255;
    else if (y) px[2] = 255;
    s.append(reinterpret_cast<char*>(px), 3);
  }
  return WriteFile(path, s);
}

}  // namespace vox::bench
