// vox::Scene: what vox-render simulates besides the camera, read from
// scene.json. Every field is optional; the defaults give a lit, shadowed,
// diffuse picture:
//   {
//     "background": [r,g,b]  or  {"top":[r,g,b], "bottom":[r,g,b]},
//                               (a gradient along the camera's up vector)
//     "background_in_exr": false, true: the EXR's R G B include the background
//                               ((1 - A) times it, as the PNG preview shows);
//                               false (default): premultiplied, a miss is 0
//     "ambient": [r,g,b],
//     "lights": [ {"type":"directional", "direction":[x,y,z], ...},
//                 {"type":"point", "position":[x,y,z], ...} ],
//         each with "color":[r,g,b], "intensity":I, "shadows":true|false;
//         "direction" is the way the light travels (from the light into
//         the scene). A point light's "falloff" is "inverse_square"
//         (default: what reaches a point at distance d is intensity / d^2,
//         d in world units) or "none" (the intensity at every distance: the
//         look before falloff). Without a "lights" key the scene has one
//         shadow-casting key light above and behind the camera; "lights":[]
//         has none.
//     "material": {"color":[r,g,b], "diffuse":kd, "specular":ks,
//                  "shininess":n, "reflect":kr, "transmit":kt, "ior":eta},
//     "materials": [ {"box":{"min":[x,y,z],"max":[x,y,z]}, ...material...} ],
//         region overrides in world space (min <= max on each axis): the
//         first box holding the hit point gives the material; elsewhere
//         "material" applies,
//     "volume": {"absorption":sa, "scattering":ss, "color":[r,g,b],
//                "ramp":[...], "emission":{...}, "blackbody":{...}, "phase_g":g,
//                "light_step":S, "light_optical_depth":D, "shadow_lod":G,
//                "light_lattice":L},
//         absorption and scattering per world unit (a number or [r,g,b]),
//         times the voxel density (fog volumes only; the shading controls
//         are described in render/fog_material.h); the quality of single scattering: the light
//         reaching a primary ray is evaluated every S voxels along it, or
//         sooner where the extinction over the step would exceed optical
//         depth D / sqrt(T) (T: the transmittance from the camera), and
//         interpolated between (S, D > 0); with a pyramid
//         a transmittance ray's cells widen by one voxel every G voxels
//         along it (G > 0; 0: exact voxels all the way), and where samples
//         lie far apart the light is kept on a lattice shared by
//         neighbouring pixels (L true, the default; false: every sample
//         traces its own transmittance rays),
//     "normals": "smooth" | "flat",  level sets' shading normals: "smooth"
//         (default) blends the stored normals of the 3x3x3 voxels around
//         the hit point (quadratic B-spline weights); "flat" shades each voxel with its own normal
//         (the hit is the same voxel either way),
//     "max_depth": D,          reflection/refraction generations (0..16)
//     "samples_per_pixel": S   (1..1024)
//   }
// Colours have no negative components. A colour stored per voxel replaces
// the material colour. Surface colour =
// (1 - reflect - transmit) * local + reflect * reflected + transmit *
// refracted, where local = colour * (ambient + sum diffuse) + specular.
//
// Thread safety: immutable value; thread-safe to read.
#ifndef VOX_RENDER_SCENE_H_
#define VOX_RENDER_SCENE_H_

#include <glm/vec3.hpp>
#include <string>
#include <string_view>
#include <vector>

#include "core/util/status.h"
#include "render/fog_material.h"

namespace vox {

struct Light {
  enum class Type { kDirectional, kPoint };
  Type type = Type::kDirectional;
  glm::dvec3 direction{0.0, -1.0, 0.0};  // unit; directional lights: travel direction
  glm::dvec3 position{0.0};              // point lights
  glm::dvec3 color{1.0};
  double intensity = 1.0;
  bool shadows = true;
  bool falloff = true;  // point lights: intensity / d^2
};

struct Material {
  glm::dvec3 color{0.8};
  double diffuse = 0.9;
  double specular = 0.15;
  double shininess = 40.0;
  double reflect = 0.0;
  double transmit = 0.0;
  double ior = 1.5;
};

struct MaterialRegion {
  glm::dvec3 min{0.0}, max{0.0};  // world box, inclusive
  Material material;
};

// The fog's shading controls (absorption, scattering, colour, ramp,
// emission, blackbody, phase: render/fog_material.h) and its sampling.
struct VolumeMedium : FogControls {
  // Voxels between evaluations of the light reaching a primary ray (closer
  // where the light bends along the ray, and, where the light is read
  // from the lattice, at most three of its spacings apart).
  double light_step = 24.0;
  // At most this optical depth between evaluations of the light, divided
  // by the square root of the transmittance from the camera.
  double light_optical_depth = 0.15;
  // Voxels along a transmittance ray per voxel of cell width (LOD
  // pyramid); 0: exact voxels. (The columns of the light-space lattice,
  // under one directional light, walk exact voxels.)
  double shadow_lod = 12.0;
  // The light kept on a lattice and interpolated (render/internal/fog_light.h);
  // false: evaluated at every sample (the reference).
  bool light_lattice = true;
};

struct Scene {
  glm::dvec3 background_top{0.32, 0.38, 0.48};
  glm::dvec3 background_bottom{0.12, 0.12, 0.14};
  // The EXR's colour includes the background (else premultiplied, without:
  // render/exr.h); the PNG preview shows it either way.
  bool background_in_exr = false;
  glm::dvec3 ambient{0.12};
  bool default_lights = true;  // no "lights" key: a key light set from the camera
  std::vector<Light> lights;
  Material material;
  std::vector<MaterialRegion> regions;
  VolumeMedium volume;
  // Level sets: shading normals interpolated from the voxels around the hit
  // point ("normals": "smooth"); false: the hit voxel's own ("flat").
  bool smooth_normals = true;
  int max_depth = 4;
  int samples_per_pixel = 1;

  // The material at world point p.
  const Material& MaterialAt(const glm::dvec3& p) const {
    for (const MaterialRegion& r : regions)
      if (p.x >= r.min.x && p.y >= r.min.y && p.z >= r.min.z && p.x <= r.max.x && p.y <= r.max.y &&
          p.z <= r.max.z)
        return r.material;
    return material;
  }
  std::string ToJson() const;
};

// Parses scene.json text; errors name `file` and the field.
StatusOr<Scene> ParseScene(std::string_view json_text, std::string_view file);
StatusOr<Scene> LoadScene(const std::string& path);

// Whether rays refract in `scene`: max_depth > 0 and a material (the
// default or a region's) transmits. Surfaces only: fog never refracts.
bool SceneRefracts(const Scene& scene);

}  // namespace vox

#endif  // VOX_RENDER_SCENE_H_
