// vox-lod-normals: which normal should a level-of-detail cell carry
// (docs/lod.md)? Measured on a vox-gen store, whose shape has an analytic
// distance and normal (tools/gen/shapes.h), for a sample of the occupied
// cells of each coarse level:
//   - "mean": the normal the pyramid stores, the mean of the cell's
//     occupied voxels' normals, renormalised (storage/lod.h);
//   - "gradient": the gradient of the coarse distance field, by central
//     differences of the exact distance at the neighbouring cells' centres
//     (the best a stored coarse distance field could give);
// each against the cell's true mean normal: the area-weighted mean of the
// shape's normal over the surface inside the cell (its normal where the
// distance is within half a sample step of 0, on a grid of 4 samples per
// voxel, at most 32 per cell side), which is what a box-filtered (supersampled) rendering of the
// cell's pixel averages. Errors are angles, and the error of Lambert
// shading max(0, n.L) in 8-bit levels over 64 fixed light directions.
//   vox-lod-normals STORE SHAPE SIZE [--cells N] [--seed S]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <string>
#include <vector>

#include <glm/geometric.hpp>

#include "storage/lod.h"
#include "storage/store.h"
#include "tools/gen/shapes.h"

namespace {

using vox::ChildOf;
using vox::ChildRef;
using vox::CompactCell;

int Fail(const std::string& m) {
  std::fprintf(stderr, "vox-lod-normals: %s\n", m.c_str());
  return 2;
}

struct Cell {
  uint64_t x, y, z;  // in the level's grid
  uint32_t brick, payload;
};

// Every occupied voxel of `store`, by descending its octree.
vox::Status Collect(vox::Store& store, std::vector<Cell>* out) {
  const vox::OctreeView v = store.view();
  struct Item {
    CompactCell cell;
    int level;
    uint64_t x, y, z;
    uint32_t brick;
    vox::BrickView pin;
  };
  std::vector<Item> stack{{v.top[0], 0, 0, 0, 0, vox::kNoBrick, {}}};
  while (!stack.empty()) {
    Item it = std::move(stack.back());
    stack.pop_back();
    const CompactCell* pool = it.brick == vox::kNoBrick ? v.top : it.pin.cells;
    for (unsigned d = 0; d < 8; ++d) {
      const ChildRef r = ChildOf(it.cell, d, it.level, v);
      if (r.kind == ChildRef::kEmpty) continue;
      const uint64_t x = it.x * 2 + (d & 1), y = it.y * 2 + ((d >> 1) & 1),
                     z = it.z * 2 + ((d >> 2) & 1);
      if (r.kind == ChildRef::kPayload) {
        out->push_back({x, y, z, it.brick, r.index});
      } else if (r.kind == ChildRef::kBrick) {
        auto b = store.FetchBrick(r.index);
        if (!b.ok()) return b.status();
        stack.push_back({b->cells[0], it.level + 1, x, y, z, r.index, *b});
      } else {
        stack.push_back({pool[r.index], it.level + 1, x, y, z, it.brick, it.pin});
      }
    }
  }
  return vox::OkStatus();
}

double AngleDeg(const glm::dvec3& a, const glm::dvec3& b) {
  return std::acos(std::clamp(glm::dot(a, b), -1.0, 1.0)) * (180.0 / 3.14159265358979323846);
}

struct Errors {
  std::vector<double> angle;
  double lambert_sum = 0;  // 8-bit levels, summed over cells x lights
  double lambert_n = 0;
  void Print(const char* name) {
    std::sort(angle.begin(), angle.end());
    const auto q = [&](double f) { return angle[size_t(f * double(angle.size() - 1))]; };
    double mean = 0;
    for (double a : angle) mean += a;
    mean /= double(angle.size());
    std::printf("  %-9s angle mean %7.3f deg  median %7.3f  p95 %7.3f  max %7.3f   lambert %6.3f levels\n",
                name, mean, q(0.5), q(0.95), angle.back(), lambert_sum / lambert_n);
  }
};

}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) return Fail("usage: vox-lod-normals STORE SHAPE SIZE [--cells N] [--seed S]");
  const std::string dir = argv[1], shape_name = argv[2];
  // A positive integer, or 0 (refused by the callers below).
  const auto count = [](const char* text) -> uint64_t {
    char* end = nullptr;
    const unsigned long long v = std::strtoull(text, &end, 10);
    return (*text == '\0' || *end != '\0' || *text == '-') ? 0 : v;
  };
  const uint64_t size = count(argv[3]);
  if (size < 2) return Fail("SIZE '" + std::string(argv[3]) + "': expected the store's grid size");
  size_t max_cells = 20000;
  uint64_t seed = 1;
  for (int i = 4; i < argc; i += 2) {
    const std::string f = argv[i];
    if (i + 1 >= argc) return Fail(f + " needs a value");
    if (f == "--cells") {
      max_cells = size_t(count(argv[i + 1]));
      if (max_cells == 0) return Fail("--cells '" + std::string(argv[i + 1]) + "': expected N > 0");
    } else if (f == "--seed") {
      seed = count(argv[i + 1]);
    } else {
      return Fail("unknown flag " + f);
    }
  }
  auto shape = vox::gen::MakeShape(shape_name, size);
  if (!shape.ok()) return Fail(shape.status().ToString());
  vox::OpenOptions oo;
  auto base = vox::Store::Open(dir, oo);
  if (!base.ok()) return Fail(base.status().ToString());
  auto pyr = vox::LodPyramid::Open(dir, **base, oo);
  if (!pyr.ok()) return Fail(pyr.status().ToString());
  const glm::dvec3 origin((*base)->meta().origin);  // VDB index of grid voxel 0
  const vox::gen::Shape& sh = **shape;

  std::vector<glm::dvec3> lights;  // 64 fixed directions, spread over the sphere
  for (int i = 0; i < 64; ++i) {
    const double z = 1 - (i + 0.5) / 32.0, r = std::sqrt(std::max(0.0, 1 - z * z));
    const double phi = i * 2.399963229728653;
    lights.push_back({r * std::cos(phi), r * std::sin(phi), z});
  }
  std::printf("vox-lod-normals %s %s %llu: %zu cells a level at most\n", dir.c_str(),
              shape_name.c_str(), (unsigned long long)size, max_cells);
  for (int l = 1; l <= (*pyr)->max_level() && l <= 4; ++l) {
    vox::Store& s = *(*pyr)->level(l);
    std::vector<Cell> cells;
    if (vox::Status st = Collect(s, &cells); !st.ok()) return Fail(st.ToString());
    std::mt19937_64 rng(seed + uint64_t(l));
    std::shuffle(cells.begin(), cells.end(), rng);
    if (cells.size() > max_cells) cells.resize(max_cells);
    const double side = std::ldexp(1.0, l);  // base voxels per cell side
    const int m = std::min(int(side) * 4, 32);  // samples per cell side
    const double h = side / m;
    Errors mean_err, grad_err;
    size_t skipped = 0;
    for (const Cell& c : cells) {
      // The cell spans [v side - 0.5, (v + 1) side - 0.5) in index space
      // (a voxel's centre is its index point).
      const glm::dvec3 lo = glm::dvec3(double(c.x), double(c.y), double(c.z)) * side + origin - 0.5;
      glm::dvec3 ref(0.0);
      for (int k = 0; k < m; ++k)
        for (int j = 0; j < m; ++j)
          for (int i = 0; i < m; ++i) {
            const glm::dvec3 p = lo + (glm::dvec3(i, j, k) + 0.5) * h;
            if (std::fabs(sh.Distance(p)) <= 0.5 * h) ref += sh.Normal(p);
          }
      if (glm::length(ref) < 1e-9) {  // no surface inside the cell (band voxels only)
        ++skipped;
        continue;
      }
      ref = glm::normalize(ref);
      auto a = s.Attributes(c.brick, c.payload);
      if (!a.ok()) return Fail(a.status().ToString());
      const glm::dvec3 mean = glm::normalize(glm::dvec3(a->normal));
      const glm::dvec3 centre = lo + 0.5 * side;
      glm::dvec3 g;
      for (int ax = 0; ax < 3; ++ax) {
        glm::dvec3 e(0.0);
        e[ax] = side;
        g[ax] = sh.Distance(centre + e) - sh.Distance(centre - e);
      }
      const glm::dvec3 grad = glm::normalize(g);
      mean_err.angle.push_back(AngleDeg(mean, ref));
      grad_err.angle.push_back(AngleDeg(grad, ref));
      for (const glm::dvec3& L : lights) {
        const double want = std::max(0.0, glm::dot(ref, L));
        mean_err.lambert_sum += 255.0 * std::fabs(std::max(0.0, glm::dot(mean, L)) - want);
        grad_err.lambert_sum += 255.0 * std::fabs(std::max(0.0, glm::dot(grad, L)) - want);
      }
      mean_err.lambert_n += double(lights.size());
      grad_err.lambert_n += double(lights.size());
    }
    if (mean_err.angle.empty()) continue;
    std::printf("level %d (cells of %g^3 voxels): %zu cells measured, %zu without surface\n", l,
                side, mean_err.angle.size(), skipped);
    mean_err.Print("mean");
    grad_err.Print("gradient");
    std::fflush(stdout);
  }
  return 0;
}
