#include "tests/study/reference.h"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <sstream>

namespace vox::testing {
namespace {

mpq_class Rational(int64_t i) {
  mpz_class z;
  mpz_set_si(z.get_mpz_t(), long(i));
  return mpq_class(z);
}

int Sign(long double x) { return x > 0 ? 1 : (x < 0 ? -1 : 0); }

uint64_t HashKey(uint64_t x, uint64_t y, uint64_t z) {
  uint64_t h = x * 0x9E3779B97F4A7C15ull ^ (y + 0x632BE59BD9B4E019ull) * 0xC2B2AE3D27D4EB4Full ^
               (z + 0x85EBCA77C2B2AE63ull) * 0x165667B19E3779F9ull;
  h ^= h >> 31;
  h *= 0xD6E8FEB86659FD93ull;
  return h ^ (h >> 29);
}

}  // namespace

// ---------------------------------------------------------------- ExactRay

ExactRay::ExactRay(const Ray& ray) : ray_(ray) {
  for (int a = 0; a < 3; ++a) {
    ol_[a] = (long double)ray.origin[a];
    dl_[a] = (long double)ray.dir[a];
    oq_[a] = mpq_class(ray.origin[a]);  // mpq_set_d: exact
    dq_[a] = mpq_class(ray.dir[a]);
  }
}

ExactRay::T ExactRay::Plane(int axis, int64_t plane) const {
  T t;
  t.axis = axis;
  t.plane = plane;
  // Two roundings to 64 bits; no overflow or underflow is possible since the
  // quotient of doubles lies within [2^-2100, 2^2100] (or is 0).
  t.approx = ((long double)plane - ol_[axis]) / dl_[axis];
  return t;
}

mpq_class ExactRay::Exact(const T& t) const {
  if (t.axis < 0) return mpq_class(0);
  mpq_class r = (Rational(t.plane) - oq_[t.axis]) / dq_[t.axis];
  return r;
}

mpq_class ExactRay::PointAt(const T& t, int a) const { return oq_[a] + Exact(t) * dq_[a]; }

int ExactRay::Compare(const T& a, const T& b) const {
  if (a.axis == b.axis && a.plane == b.plane) return 0;
  // approx is exactly zero iff the value is, and its sign is always exact.
  if (a.approx == 0 || b.approx == 0) return Sign(a.approx - b.approx);
  long double diff = a.approx - b.approx;
  long double m = std::max(std::fabs(a.approx), std::fabs(b.approx));
  if (std::fabs(diff) > m * 0x1p-58L) return Sign(diff);
  ++exact_fallbacks;
  const int c = cmp(Exact(a), Exact(b));
  return c < 0 ? -1 : (c > 0 ? 1 : 0);
}

// ---------------------------------------------------------------- contacts

Contact BoxContact(const ExactRay& ray, const int64_t lo[3], const int64_t hi[3]) {
  Contact c;
  ExactRay::T tin = ray.Zero(), tout;
  bool have_out = false, half_open_ok = true;
  for (int a = 0; a < 3; ++a) {
    long double d = ray.d(a);
    if (d == 0) {
      long double o = ray.o(a);
      if (o < (long double)lo[a] || o > (long double)hi[a]) return c;
      if (o == (long double)hi[a]) half_open_ok = false;
      continue;
    }
    const bool pos = d > 0;
    ExactRay::T en = ray.Plane(a, pos ? lo[a] : hi[a]);
    ExactRay::T ex = ray.Plane(a, pos ? hi[a] : lo[a]);
    if (ex.approx < 0) return c;  // exact sign: the box is behind the origin
    if (ray.Compare(en, tin) > 0) tin = en;
    if (!have_out || ray.Compare(ex, tout) < 0) tout = ex;
    have_out = true;
  }
  c.tin = tin;
  c.tout = tout;
  const int cmp_io = ray.Compare(tin, tout);
  c.touch = cmp_io <= 0;
  c.meets = cmp_io < 0 && half_open_ok;
  return c;
}

Contact VoxelContact(const ExactRay& ray, const Voxel& v) {
  int64_t lo[3] = {v[0], v[1], v[2]};
  int64_t hi[3] = {v[0] + 1, v[1] + 1, v[2] + 1};
  return BoxContact(ray, lo, hi);
}

// ---------------------------------------------------------------- Reference

uint8_t* Reference::Table::Find(uint64_t x, uint64_t y, uint64_t z, bool insert) {
  if (insert && (count + 1) * 2 > slots.size()) {
    std::vector<Slot> old;
    old.swap(slots);
    slots.assign(std::max<size_t>(16, old.size() * 2), Slot{});
    count = 0;
    for (const Slot& s : old)
      if (s.used) *Find(s.x, s.y, s.z, true) = s.mask;
  }
  if (slots.empty()) return nullptr;
  const size_t m = slots.size() - 1;
  for (size_t i = HashKey(x, y, z) & m;; i = (i + 1) & m) {
    Slot& s = slots[i];
    if (!s.used) {
      if (!insert) return nullptr;
      s.used = true;
      s.x = x;
      s.y = y;
      s.z = z;
      s.mask = 0;
      ++count;
      return &s.mask;
    }
    if (s.x == x && s.y == y && s.z == z) return &s.mask;
  }
}

uint8_t Reference::Table::Get(uint64_t x, uint64_t y, uint64_t z) const {
  uint8_t* m = const_cast<Table*>(this)->Find(x, y, z, false);
  return m ? *m : 0;
}

Reference::Reference(const std::vector<Voxel>& voxels, int levels) : levels_(levels) {
  tables_.resize(levels + 1);
  for (const Voxel& v : voxels) {
    for (int k = 1; k <= levels; ++k) {
      uint64_t x = uint64_t(v[0]) >> k, y = uint64_t(v[1]) >> k, z = uint64_t(v[2]) >> k;
      unsigned digit = unsigned((v[0] >> (k - 1)) & 1) | unsigned(((v[1] >> (k - 1)) & 1) << 1) |
                       unsigned(((v[2] >> (k - 1)) & 1) << 2);
      uint8_t* m = tables_[k].Find(x, y, z, true);
      if (*m & (1u << digit)) break;  // this cell and all above are recorded
      if (k == 1) ++num_voxels_;
      *m |= uint8_t(1u << digit);
    }
  }
}

bool Reference::Occupied(const Voxel& v) const {
  const int64_t n = int64_t(1) << levels_;
  for (int a = 0; a < 3; ++a)
    if (v[a] < 0 || v[a] >= n) return false;
  unsigned digit = unsigned(v[0] & 1) | unsigned((v[1] & 1) << 1) | unsigned((v[2] & 1) << 2);
  return (tables_[1].Get(uint64_t(v[0]) >> 1, uint64_t(v[1]) >> 1, uint64_t(v[2]) >> 1) >>
          digit) & 1;
}

struct Reference::Search {
  explicit Search(const ExactRay& r) : ray(r) {}
  const ExactRay& ray;
  bool all = false;
  bool has_best = false;
  Voxel best{};
  ExactRay::T best_tin;
  std::vector<std::pair<Voxel, ExactRay::T>> touched;
  std::vector<RefContact>* out = nullptr;
  // A cell whose entry is after the best entry cannot matter.
  bool Pruned(const ExactRay::T& tin) const {
    return !all && has_best && ray.Compare(tin, best_tin) > 0;
  }
};

void Reference::Visit(Search& s, int k, const uint64_t c[3]) const {
  const uint8_t mask = tables_[k].Get(c[0], c[1], c[2]);
  struct Kid {
    uint64_t c[3];
    Contact ct;
  };
  Kid kids[8];
  int n = 0;
  const int sub = k - 1;
  for (unsigned dg = 0; dg < 8; ++dg) {
    if (!((mask >> dg) & 1)) continue;
    Kid kid;
    int64_t lo[3], hi[3];
    for (int a = 0; a < 3; ++a) {
      kid.c[a] = 2 * c[a] + ((dg >> a) & 1);
      lo[a] = int64_t(kid.c[a] << sub);
      hi[a] = int64_t((kid.c[a] + 1) << sub);
    }
    kid.ct = BoxContact(s.ray, lo, hi);
    if (!kid.ct.touch || s.Pruned(kid.ct.tin)) continue;
    // Insertion by entry parameter.
    int j = n++;
    while (j > 0 && s.ray.Compare(kid.ct.tin, kids[j - 1].ct.tin) < 0) {
      kids[j] = kids[j - 1];
      --j;
    }
    kids[j] = kid;
  }
  for (int i = 0; i < n; ++i) {
    const Kid& kid = kids[i];
    if (s.Pruned(kid.ct.tin)) break;
    if (sub > 0) {
      Visit(s, sub, kid.c);
      continue;
    }
    Voxel v = {int64_t(kid.c[0]), int64_t(kid.c[1]), int64_t(kid.c[2])};
    if (s.all) {
      s.out->push_back({v, kid.ct});
    } else if (kid.ct.meets && (!s.has_best || s.ray.Compare(kid.ct.tin, s.best_tin) < 0)) {
      if (s.has_best) s.touched.push_back({s.best, s.best_tin});
      s.has_best = true;
      s.best = v;
      s.best_tin = kid.ct.tin;
    } else {
      s.touched.push_back({v, kid.ct.tin});
    }
  }
}

RefHit Reference::FirstHit(const ExactRay& ray) const {
  RefHit r;
  if (num_voxels_ == 0) return r;
  const int64_t g = int64_t(1) << levels_;
  int64_t lo[3] = {0, 0, 0}, hi[3] = {g, g, g};
  if (!BoxContact(ray, lo, hi).touch) return r;
  Search s(ray);
  const uint64_t root[3] = {0, 0, 0};
  Visit(s, levels_, root);
  r.hit = s.has_best;
  r.voxel = s.best;
  r.tin = s.best_tin;
  for (const auto& [v, t] : s.touched)
    if (!s.has_best || ray.Compare(t, s.best_tin) <= 0) r.touched.push_back(v);
  r.ambiguous = r.hit && !r.touched.empty();
  return r;
}

std::vector<RefContact> Reference::AllTouched(const ExactRay& ray) const {
  std::vector<RefContact> out;
  if (num_voxels_ == 0) return out;
  const int64_t g = int64_t(1) << levels_;
  int64_t lo[3] = {0, 0, 0}, hi[3] = {g, g, g};
  if (!BoxContact(ray, lo, hi).touch) return out;
  Search s(ray);
  s.all = true;
  s.out = &out;
  const uint64_t root[3] = {0, 0, 0};
  Visit(s, levels_, root);
  std::stable_sort(out.begin(), out.end(), [&](const RefContact& a, const RefContact& b) {
    return ray.Compare(a.contact.tin, b.contact.tin) < 0;
  });
  return out;
}

// ---------------------------------------------------------------- checks

std::string RayString(const Ray& ray) {
  char buf[256];
  std::snprintf(buf, sizeof buf, "origin (%a, %a, %a) dir (%a, %a, %a)", ray.origin.x,
                ray.origin.y, ray.origin.z, ray.dir.x, ray.dir.y, ray.dir.z);
  return buf;
}

std::string VoxelString(const Voxel& v) {
  return "(" + std::to_string(v[0]) + ", " + std::to_string(v[1]) + ", " + std::to_string(v[2]) +
         ")";
}

Voxel ToVoxel(const Hit& h) { return {h.voxel.x, h.voxel.y, h.voxel.z}; }

namespace {

std::string TString(const ExactRay::T& t) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.17Lg", t.approx);
  return buf;
}

// The tracer's t against the exact entry parameter: relative 1e-9, or
// absolute 1e-9 near 0. An exact t beyond the double range must come back as
// +inf (or the largest doubles), the correctly rounded answer.
std::string CheckT(double got, const ExactRay::T& exact) {
  const long double e = exact.approx;
  if (e > (long double)DBL_MAX) {
    if (got >= DBL_MAX * (1 - 1e-9)) return "";
  } else if (std::fabs((long double)got - e) <= 1e-9L * std::max(1.0L, e)) {
    return "";
  }
  char buf[128];
  std::snprintf(buf, sizeof buf, "tracer t %.17g, exact entry %.17Lg", got, e);
  return buf;
}

}  // namespace

std::string CheckFirstHit(const Reference& ref, const ExactRay& ray, const RefHit& expected,
                          const std::optional<Hit>& got) {
  const std::string where = " [" + RayString(ray.ray()) + "]";
  std::string ref_desc = expected.hit ? "reference hits " + VoxelString(expected.voxel) +
                                            " at t " + TString(expected.tin) +
                                            (expected.ambiguous ? " (ambiguous)" : "")
                                      : "reference misses";
  if (expected.hit && !got) return "tracer missed; " + ref_desc + where;
  if (!got) return "";
  const Voxel g = ToVoxel(*got);
  const std::string got_desc = "tracer hit " + VoxelString(g) + "; " + ref_desc;
  if (expected.hit && !expected.ambiguous) {
    if (g != expected.voxel) return got_desc + where;
    std::string e = CheckT(got->t, expected.tin);
    return e.empty() ? e : e + " at " + VoxelString(g) + where;
  }
  if (!ref.Occupied(g)) return got_desc + ", and its voxel is empty" + where;
  Contact c = VoxelContact(ray, g);
  if (!c.touch) return got_desc + ", and the ray does not touch its voxel" + where;
  if (expected.hit && ray.Compare(c.tin, expected.tin) > 0)
    return got_desc + ", and its voxel is touched only at t " + TString(c.tin) + where;
  std::string e = CheckT(got->t, c.tin);
  return e.empty() ? e : e + " at " + VoxelString(g) + where;
}

namespace {

struct RationalContact {
  bool touch = false;
  mpq_class tin, tout;
};

// The ray against the closed box [v - eps, v + 1 + eps]^3, in rationals.
RationalContact GrownContact(const Ray& ray, const Voxel& v, const mpq_class& eps) {
  RationalContact c;
  mpq_class tin(0);
  std::optional<mpq_class> tout;
  for (int a = 0; a < 3; ++a) {
    mpq_class o(ray.origin[a]), d(ray.dir[a]);
    mpq_class lo = mpq_class(double(v[a])) - eps, hi = mpq_class(double(v[a] + 1)) + eps;
    if (d == 0) {
      if (o < lo || o > hi) return c;
      continue;
    }
    mpq_class t1 = (lo - o) / d, t2 = (hi - o) / d;
    if (t1 > t2) std::swap(t1, t2);
    if (t1 > tin) tin = t1;
    if (!tout || t2 < *tout) tout = t2;
  }
  c.touch = tin <= *tout;
  c.tin = tin;
  c.tout = *tout;
  return c;
}

}  // namespace

bool WithinEpsilon(const Reference& ref, const ExactRay& ray, const RefHit& expected,
                   const std::optional<Hit>& got, double eps) {
  const Ray& r = ray.ray();
  const mpq_class e(eps);
  double m = std::max({std::fabs(r.dir.x), std::fabs(r.dir.y), std::fabs(r.dir.z)});
  const mpq_class eps_t = e / mpq_class(m);  // eps along the ray, in t
  std::optional<mpq_class> got_t;
  if (got) {
    if (!ref.Occupied(ToVoxel(*got))) return false;
    RationalContact c = GrownContact(r, ToVoxel(*got), e);
    if (!c.touch) return false;
    if (!expected.hit || c.tin <= ray.Exact(expected.tin) + eps_t) return true;
    got_t = c.tin;
  }
  // Every voxel met before the tracer's answer (all of them on a miss) is
  // met over less than eps.
  for (const RefContact& rc : ref.AllTouched(ray)) {
    if (!rc.contact.meets) continue;
    mpq_class tin = ray.Exact(rc.contact.tin);
    if (got_t && tin + eps_t >= *got_t) break;
    if (ray.Exact(rc.contact.tout) - tin >= eps_t) return false;
  }
  return true;
}

std::string CheckTraversal(const Reference& ref, const ExactRay& ray,
                           const std::vector<Hit>& got) {
  const std::string where = " [" + RayString(ray.ray()) + "]";
  std::vector<RefContact> all = ref.AllTouched(ray);
  std::map<Voxel, Contact> touched;
  for (const RefContact& rc : all) touched[rc.voxel] = rc.contact;
  std::set<Voxel> seen;
  const ExactRay::T* prev = nullptr;
  for (size_t i = 0; i < got.size(); ++i) {
    const Voxel g = ToVoxel(got[i]);
    auto it = touched.find(g);
    if (it == touched.end())
      return "visit " + std::to_string(i) + ": " + VoxelString(g) +
             (ref.Occupied(g) ? " is not touched by the ray" : " is empty") + where;
    if (!seen.insert(g).second) return "visit " + std::to_string(i) + ": " + VoxelString(g) +
                                       " visited twice" + where;
    if (prev && ray.Compare(*prev, it->second.tin) > 0)
      return "visit " + std::to_string(i) + ": " + VoxelString(g) + " entered at t " +
             TString(it->second.tin) + ", before the previous visit's " + TString(*prev) + where;
    prev = &it->second.tin;
    std::string e = CheckT(got[i].t, it->second.tin);
    if (!e.empty()) return "visit " + std::to_string(i) + ": " + e + where;
  }
  for (const RefContact& rc : all)
    if (rc.contact.meets && !seen.count(rc.voxel))
      return "tracer never visited " + VoxelString(rc.voxel) + ", met at t " +
             TString(rc.contact.tin) + " (" + std::to_string(got.size()) + " visits)" + where;
  return "";
}

}  // namespace vox::testing
