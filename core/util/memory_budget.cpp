#include "core/util/memory_budget.h"

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <malloc.h>
#include <unistd.h>
#include <sstream>
#include <string>
#include <vector>

namespace vox {
namespace {

// cgroup v1 writes "no limit" as LONG_MAX rounded down to a page (or other
// huge numbers); anything this large is unlimited.
constexpr uint64_t kUnlimited = uint64_t(1) << 62;

std::string Join(const std::string& root, const std::string& path) {
  if (root.empty() || root == "/") return path;
  std::string r = root;
  while (!r.empty() && r.back() == '/') r.pop_back();
  return r + (path.empty() || path[0] != '/' ? "/" : "") + path;
}

// The whole file, or false when it cannot be opened.
bool ReadFile(const std::string& path, std::string* out) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return false;
  std::ostringstream ss;
  ss << in.rdbuf();
  *out = ss.str();
  return true;
}

std::vector<std::string> Split(const std::string& s, char sep) {
  std::vector<std::string> parts;
  size_t start = 0;
  for (;;) {
    size_t p = s.find(sep, start);
    parts.push_back(s.substr(start, p == std::string::npos ? std::string::npos : p - start));
    if (p == std::string::npos) return parts;
    start = p + 1;
  }
}

// Reads a limit file: a decimal number of bytes or "max". Sets *bytes to 0 for
// unlimited. False (not an error) when the file does not exist.
StatusOr<bool> ReadLimitFile(const std::string& path, uint64_t* bytes) {
  std::string text;
  if (!ReadFile(path, &text)) return false;
  while (!text.empty() && std::isspace(static_cast<unsigned char>(text.back()))) text.pop_back();
  if (text == "max") {
    *bytes = 0;
    return true;
  }
  errno = 0;
  char* end = nullptr;
  unsigned long long v = std::strtoull(text.c_str(), &end, 10);
  if (text.empty() || text[0] == '-' || end == text.c_str() || *end != '\0' || errno == ERANGE)
    return CorruptionError(path + ": expected a number of bytes or \"max\", got '" + text + "'");
  *bytes = v >= kUnlimited ? 0 : uint64_t(v);
  return true;
}

// One line of /proc/self/mountinfo, the fields we use.
struct Mount {
  std::string root;         // the path of the mount's root within its hierarchy
  std::string mount_point;  // where it is mounted
  std::string fstype;       // "cgroup" or "cgroup2"
  std::string super_options;
};

std::vector<Mount> ParseMountInfo(const std::string& text) {
  std::vector<Mount> mounts;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    // id parent major:minor root mount_point options [optional...] - fstype source super_options
    std::vector<std::string> f;
    std::istringstream ls(line);
    std::string w;
    while (ls >> w) f.push_back(w);
    auto dash = std::find(f.begin(), f.end(), "-");
    if (f.size() < 5 || dash == f.end() || f.end() - dash < 4) continue;
    mounts.push_back({f[3], f[4], dash[1], dash[3]});
  }
  return mounts;
}

bool HasOption(const std::string& options, const std::string& name) {
  for (const std::string& o : Split(options, ','))
    if (o == name) return true;
  return false;
}

// The directory of cgroup `path` (from /proc/self/cgroup) under `mount`, or
// empty when the cgroup is not visible through it. A mount of a sub-tree
// (containers) has root "/a/b": the cgroup "/a/b/c" is mount_point/c.
std::string CgroupDir(const Mount& mount, const std::string& path) {
  std::string root = mount.root == "/" ? "" : mount.root;
  if (!root.empty()) {
    if (path.compare(0, root.size(), root) != 0 ||
        (path.size() > root.size() && path[root.size()] != '/'))
      return "";
    return mount.mount_point + path.substr(root.size());
  }
  return mount.mount_point + (path == "/" ? "" : path);
}

// The tightest limit in `file` from `dir` up to `top` (inclusive), if any.
Status TightestLimit(const std::string& root, std::string dir, const std::string& top,
                     const std::string& file, MemoryLimit* out) {
  for (;;) {
    uint64_t bytes = 0;
    const std::string path = Join(root, dir + "/" + file);
    VOX_ASSIGN_OR_RETURN(bool found, ReadLimitFile(path, &bytes));
    if (found && bytes != 0 && (out->cgroup_bytes == 0 || bytes < out->cgroup_bytes)) {
      out->cgroup_bytes = bytes;
      out->cgroup_file = path;
    }
    if (dir.size() <= top.size()) return OkStatus();
    size_t slash = dir.find_last_of('/');
    if (slash == std::string::npos || slash < top.size()) return OkStatus();
    dir = dir.substr(0, slash);
  }
}

std::string FormatMiB(uint64_t bytes) {
  char buf[32];
  snprintf(buf, sizeof buf, "%.1f", double(bytes) / double(kMiB));
  return buf;
}

// Rounded up to 0.1 MiB: a stated need that, given back, suffices.
std::string FormatMiBUp(uint64_t bytes) {
  const uint64_t tenth = kMiB / 10;
  char buf[32];
  snprintf(buf, sizeof buf, "%.1f", double((bytes + tenth - 1) / tenth) / 10.0);
  return buf;
}

}  // namespace

std::string MemoryLimit::ToString() const {
  if (bytes == 0) return "no limit found";
  std::string s = FormatMiB(bytes) + " MiB (";
  s += cgroup_bytes == bytes ? "cgroup " + cgroup_file : std::string("MemAvailable");
  if (cgroup_bytes != 0 && mem_available != 0)
    s += "; cgroup " + FormatMiB(cgroup_bytes) + ", MemAvailable " + FormatMiB(mem_available) + " MiB";
  return s + ")";
}

StatusOr<MemoryLimit> DetectMemoryLimit(const std::string& root) {
  MemoryLimit out;
  std::string cgroups, mountinfo;
  if (ReadFile(Join(root, "/proc/self/cgroup"), &cgroups) &&
      ReadFile(Join(root, "/proc/self/mountinfo"), &mountinfo)) {
    const std::vector<Mount> mounts = ParseMountInfo(mountinfo);
    std::istringstream in(cgroups);
    std::string line;
    while (std::getline(in, line)) {
      // hierarchy-id:controllers:path; v2 is "0::path".
      size_t a = line.find(':'), b = a == std::string::npos ? a : line.find(':', a + 1);
      if (b == std::string::npos) continue;
      const std::string controllers = line.substr(a + 1, b - a - 1), path = line.substr(b + 1);
      const bool v2 = line.compare(0, a, "0") == 0 && controllers.empty();
      if (!v2 && !HasOption(controllers, "memory")) continue;
      for (const Mount& m : mounts) {
        if (v2 ? m.fstype != "cgroup2" : (m.fstype != "cgroup" || !HasOption(m.super_options, "memory")))
          continue;
        std::string dir = CgroupDir(m, path);
        if (dir.empty()) continue;
        VOX_RETURN_IF_ERROR(TightestLimit(root, dir, m.mount_point, v2 ? "memory.max" : "memory.limit_in_bytes",
                                          &out));
      }
    }
  }
  std::string meminfo;
  if (ReadFile(Join(root, "/proc/meminfo"), &meminfo)) {
    std::istringstream in(meminfo);
    std::string line;
    while (std::getline(in, line)) {
      if (line.compare(0, 13, "MemAvailable:") != 0) continue;
      unsigned long long kb = 0;
      char unit[8] = {0};
      if (sscanf(line.c_str() + 13, "%llu %7s", &kb, unit) != 2 || std::string(unit) != "kB")
        return CorruptionError(Join(root, "/proc/meminfo") + ": cannot parse '" + line + "'");
      out.mem_available = uint64_t(kb) * 1024;
    }
  }
  out.bytes = out.cgroup_bytes;
  if (out.mem_available != 0 && (out.bytes == 0 || out.mem_available < out.bytes))
    out.bytes = out.mem_available;
  return out;
}

ProcessMemory ReadProcessMemory() {
  ProcessMemory m;
  if (FILE* f = std::fopen("/proc/self/status", "re")) {
    char line[256];
    unsigned long long kb = 0;
    while (std::fgets(line, sizeof(line), f) != nullptr) {
      if (std::sscanf(line, "VmHWM: %llu kB", &kb) == 1) m.peak_rss = uint64_t(kb) << 10;
      if (std::sscanf(line, "RssAnon: %llu kB", &kb) == 1) m.rss_anon = uint64_t(kb) << 10;
      if (std::sscanf(line, "VmRSS: %llu kB", &kb) == 1) m.rss = uint64_t(kb) << 10;
      if (std::sscanf(line, "VmSize: %llu kB", &kb) == 1) m.vm_size = uint64_t(kb) << 10;
    }
    std::fclose(f);
  }
#if defined(__GLIBC__) && (__GLIBC__ > 2 || __GLIBC_MINOR__ >= 33)
  const struct mallinfo2 mi = mallinfo2();
  m.heap_held = uint64_t(mi.arena) + uint64_t(mi.hblkhd);
  m.heap_in_use = uint64_t(mi.uordblks) + uint64_t(mi.hblkhd);
#endif
  return m;
}

HeapWatch& HeapWatch::Process() {
  static HeapWatch watch;
  return watch;
}

void HeapWatch::SetTarget(uint64_t anon_bytes) {
  std::lock_guard<std::mutex> lock(mu_);
  target_.store(anon_bytes, std::memory_order_relaxed);
  high_ = 0;
  given_up_.store(0, std::memory_order_relaxed);
}

uint64_t HeapWatch::Loaded(uint64_t bytes) {
  if (target_.load(std::memory_order_relaxed) == 0) return 0;
  const uint64_t before = loaded_.fetch_add(bytes, std::memory_order_relaxed);
  if ((before + bytes) / kCheckBytes == before / kCheckBytes) return 0;
  // statm: size resident shared ... in pages; resident - shared is the
  // anonymous part (RssAnon), read in a few microseconds.
  FILE* f = std::fopen("/proc/self/statm", "re");
  if (f == nullptr) return 0;
  unsigned long long size = 0, resident = 0, shared = 0;
  const int n = std::fscanf(f, "%llu %llu %llu", &size, &resident, &shared);
  std::fclose(f);
  if (n != 3 || shared > resident) return 0;
  static const uint64_t page = uint64_t(sysconf(_SC_PAGESIZE));
  return Absorb(uint64_t(resident - shared) * page);
}

uint64_t HeapWatch::Absorb(uint64_t anon) {
  std::lock_guard<std::mutex> lock(mu_);
  const uint64_t target = target_.load(std::memory_order_relaxed);
  if (target == 0) return 0;
  const uint64_t floor = std::max(target, high_);
  if (anon <= floor) return 0;
  high_ = anon;
  given_up_.fetch_add(anon - floor, std::memory_order_relaxed);
  return anon - floor;
}

std::string ProcessMemory::ToJson() const {
  std::ostringstream o;
  o << "{\"peak_rss\": " << peak_rss << ", \"rss\": " << rss << ", \"vm_size\": " << vm_size
    << ", \"rss_anon\": " << rss_anon
    << ", \"heap_held\": " << heap_held << ", \"heap_in_use\": " << heap_in_use << "}";
  return o.str();
}

StatusOr<uint64_t> ParseMemorySize(std::string_view flag, std::string_view text) {
  const std::string f(flag), t(text);
  auto bad = [&](const std::string& why) {
    return InvalidArgumentError(f + " '" + t + "': " + why);
  };
  if (t.empty()) return bad("expected a size such as 512 (MiB), 512M or 2G");
  size_t i = 0;
  while (i < t.size() && (std::isdigit(static_cast<unsigned char>(t[i])) || t[i] == '.')) ++i;
  if (i == 0) {
    if (t[0] == '-') return bad("must be positive");
    return bad("not a number; expected a size such as 512 (MiB), 512M or 2G");
  }
  const std::string number = t.substr(0, i);
  std::string unit = t.substr(i);
  for (char& c : unit) c = char(std::toupper(static_cast<unsigned char>(c)));
  int shift = 20;  // no unit: MiB
  if (!unit.empty()) {
    const char u = unit[0];
    const std::string rest = unit.substr(1);
    if (rest != "" && rest != "B" && rest != "IB") return bad("unknown unit '" + t.substr(i) + "'; use K, M, G or T");
    if (u == 'K') shift = 10;
    else if (u == 'M') shift = 20;
    else if (u == 'G') shift = 30;
    else if (u == 'T') shift = 40;
    else return bad("unknown unit '" + t.substr(i) + "'; use K, M, G or T");
  }
  if (std::count(number.begin(), number.end(), '.') > 1 || number == ".")
    return bad("not a number; expected a size such as 512 (MiB), 512M or 2G");
  double bytes = 0;
  if (number.find('.') == std::string::npos) {
    errno = 0;
    unsigned long long v = std::strtoull(number.c_str(), nullptr, 10);
    if (errno == ERANGE || v > (kUnlimited >> shift)) return bad("too large (at most 2^62 bytes)");
    if (v == 0) return bad("must be positive");
    const uint64_t b = uint64_t(v) << shift;
    if (b < kMiB) return bad("below 1 MiB");
    return b;
  }
  bytes = std::strtod(number.c_str(), nullptr) * std::ldexp(1.0, shift);
  if (!std::isfinite(bytes) || bytes > double(kUnlimited)) return bad("too large (at most 2^62 bytes)");
  if (bytes <= 0) return bad("must be positive");
  if (bytes < double(kMiB)) return bad("below 1 MiB");
  return uint64_t(bytes);
}

uint64_t MinBrickCacheBytes(const BudgetInputs& in) {
  // Each thread may be loading one brick while the others' are held: four
  // bricks per thread, and never under 4 MiB.
  return std::max<uint64_t>({4 * kMiB, in.min_cache_bytes,
                             uint64_t(4) * uint64_t(std::max(in.threads, 1)) * in.max_brick_bytes});
}

StatusOr<MemoryBudget> SplitMemoryBudget(uint64_t total, const BudgetInputs& in) {
  if (in.threads < 1 || in.tile_size < 1 || in.image_width < 1 || in.image_height < 1 ||
      in.channels < 1 || in.pins_per_thread < 1 || in.pins_per_thread > 256)
    return InvalidArgumentError("memory budget: threads, tile size, image size and channels must be positive, "
                                "pins per thread 1..256");
  const uint64_t threads = uint64_t(in.threads), tile = uint64_t(in.tile_size),
                 ch = uint64_t(in.channels);
  MemoryBudget b;
  b.total = total;
  b.process_base = in.process_base;
  b.headroom = total / 8;
  b.resident_top = in.resident_bytes;
  // One TileBuffer (tile^2 floats per channel) per thread.
  const uint64_t tile_bytes = tile * tile * ch * sizeof(float);
  b.tile_buffers = threads * tile_bytes;
  // The EXR writer: per thread a tile in OpenEXR's frame buffer and its
  // compressed copy; the tile offset table; the preview's one row of tiles.
  const uint64_t tiles = ((uint64_t(in.image_width) + tile - 1) / tile) *
                         ((uint64_t(in.image_height) + tile - 1) / tile);
  b.exr_writer = threads * 2 * tile_bytes + tiles * sizeof(uint64_t) +
                 uint64_t(in.image_width) * tile * 4 * sizeof(float);
  // Pages of the brick file that reads in flight touch: the record and the
  // kernel's read-ahead window (128 KiB by default) on each side, or a record
  // window (read into a buffer before the window cache takes it, and in the
  // page cache); a prefetching I/O thread's run, in its buffer and in the
  // page cache.
  b.page_cache = std::max<uint64_t>(2 * kMiB, threads * (in.max_stored_brick_bytes + 256 * 1024 +
                                                         2 * in.read_window_bytes)) +
                 uint64_t(std::max(in.io_threads, 0)) * 2 * kPrefetchRunBytes;
  const uint64_t fixed = b.process_base + b.headroom + b.resident_top + b.tile_buffers + b.exr_writer +
                         b.page_cache;
  const uint64_t min_cache = MinBrickCacheBytes(in);
  const uint64_t min_pins = threads * in.max_brick_bytes;  // one pin per thread
  auto need = [&] {
    const uint64_t n = fixed - b.headroom + min_cache + min_pins;
    // headroom is total / 8: total >= n * 8 / 7.
    return (n * 8 + 6) / 7;
  };
  auto too_small = [&] {
    return ResourceExhaustedError(
        "memory budget of " + FormatMiB(total) + " MiB is too small: the render needs at least " +
        FormatMiBUp(need()) + " MiB (--memory-mb " + std::to_string((need() + kMiB - 1) / kMiB) +
        ", or a memory limit that large; in MiB: process " + FormatMiB(b.process_base) +
        ", resident top " + FormatMiB(b.resident_top) + ", tile buffers " +
        FormatMiB(b.tile_buffers) + ", EXR writer " + FormatMiB(b.exr_writer) + ", page cache " +
        FormatMiB(b.page_cache) + ", brick cache " + FormatMiB(min_cache) + ", pins " +
        FormatMiB(min_pins) + ", headroom 1/8)");
  };
  if (fixed + min_cache + min_pins > total) return too_small();
  const uint64_t left = total - fixed;
  int pins = in.pins_per_thread;
  while (pins > 1 && (threads * uint64_t(pins) * in.max_brick_bytes > left / 8 ||
                      left - threads * uint64_t(pins) * in.max_brick_bytes < min_cache))
    pins /= 2;
  b.pins_per_thread = pins;
  b.brick_pins = threads * uint64_t(pins) * in.max_brick_bytes;
  const uint64_t rest = left - b.brick_pins;
  if (rest < min_cache) return too_small();
  if (in.cache_override != 0) {
    if (in.cache_override > rest)
      return InvalidArgumentError("brick cache of " + FormatMiB(in.cache_override) +
                                  " MiB does not fit: the memory budget of " + FormatMiB(total) +
                                  " MiB leaves " + FormatMiB(rest) + " MiB for it");
    if (in.cache_override < min_cache)
      return InvalidArgumentError("brick cache of " + FormatMiB(in.cache_override) +
                                  " MiB is below the " + FormatMiB(min_cache) + " MiB its threads need");
    b.brick_cache = in.cache_override;
    b.unused = rest - in.cache_override;
  } else {
    b.brick_cache = rest;
  }
  return b;
}

std::string MemoryBudget::ToString() const {
  std::string s = "budget " + FormatMiB(total) + " MiB: base " + FormatMiB(process_base) + ", headroom " +
                  FormatMiB(headroom) + ", top " + FormatMiB(resident_top) + ", tiles " +
                  FormatMiB(tile_buffers) + ", exr " + FormatMiB(exr_writer) + ", page cache " +
                  FormatMiB(page_cache) + ", pins " + FormatMiB(brick_pins) + " (" +
                  std::to_string(pins_per_thread) + "/thread), cache " + FormatMiB(brick_cache) + " MiB";
  if (unused != 0) s += ", unused " + FormatMiB(unused) + " MiB";
  return s;
}

std::string MemoryBudget::ToJson() const {
  std::ostringstream o;
  o << "{\"total\": " << total << ", \"process_base\": " << process_base << ", \"headroom\": " << headroom
    << ", \"resident_top\": " << resident_top << ", \"tile_buffers\": " << tile_buffers
    << ", \"exr_writer\": " << exr_writer << ", \"page_cache\": " << page_cache
    << ", \"brick_pins\": " << brick_pins << ", \"pins_per_thread\": " << pins_per_thread
    << ", \"brick_cache\": " << brick_cache << ", \"unused\": " << unused << "}";
  return o.str();
}

}  // namespace vox
