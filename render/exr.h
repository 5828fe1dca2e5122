// OpenEXR output of vox-render: the tile buffers the renderer fills, a
// tiled-EXR writer that takes tiles in any order as they finish (so memory
// stays bounded by the tiles in flight, whatever the image size), reading
// back (tests, vox-merge, previews) and the PNG preview. docs/usage.md
// describes the layout for users.
//
// Channels (premultiplied alpha, as compositors expect):
//   R, G, B  the colour premultiplied by A: a miss is 0, 0, 0; a fog pixel is
//            the light it scatters towards the camera, without background.
//            With the scene's "background_in_exr" (render/scene.h) the
//            background is added, (1 - A) times it, as the PNG preview shows.
//   A        coverage: 1 where the pixel's ray hit, 0 on a miss, the covered
//            fraction of several samples, 1 - transmittance for fog.
//   Z        planar camera depth of the first hit: the distance from the
//            camera along the view axis (camera-space z), +inf on a miss.
// and on request (ImageLayers):
//   N.X N.Y N.Z      world-space unit normal of the hit (0 on a miss and fog);
//   voxel.i .j .k    OpenVDB index coordinates of the hit voxel (exact up to
//                    2^24); NaN on a miss and on fog pixels;
//   P.X P.Y P.Z      world position of the first hit (0 on a miss);
//   distance         world distance from the camera along the pixel's ray to
//                    the first hit (Z is the planar depth), +inf on
//                    a miss.
// R, G, B and A are HALF
// unless ImageLayers::float_color asks for FLOAT (vox-render --float); the
// others are always FLOAT. Tiles are compressed as the writer is told
// (ExrCompression): vox-render's frames RLE, its parts none, vox-merge's
// output ZIP at zlib's fastest level. A part of `--tiles I/N` holds only its
// own tiles (the others are missing): it is an input of vox-merge, not an
// image for other tools.
// Header: string attributes vox:camera, vox:scene, vox:store, vox:split, vox:part ("I/N"),
// vox:frame ("N/COUNT"), vox:tileOrder, vox:storeId (the store's store_id, hex),
// plus renderTimeSeconds (float, as pbrt) and vox:timings (JSON), which are
// patched in place after the last tile. With the camera's
// ExrCameraAttributes (render/camera.h, StandardCameraAttributes: the frame
// loop and vox-merge pass them), the writer adds OpenEXR's standard camera
// attributes (ImfStandardAttributes.h), so a compositor can place the
// pixels in 3D: worldToCamera (M44f, row vectors: x right, y up, z along the
// view, origin at the camera position), worldToNDC (M44f: a world point p
// maps to (x/w, y/w) with (x, y, z, w) = (p, 1) * M; (0, 0) is the image's
// top-left corner, (1, 1) its bottom-right, so pixel (i, j)'s centre is
// ((i + 0.5)/W, (j + 0.5)/H)), and the screen window (centre (0, 0), width
// 2 tan(fov/2) on the camera-space plane z = 1 for perspective cameras,
// ortho_width for orthographic ones). vox-merge keeps them: it computes them
// again from the parts' vox:camera.
//
// Every file is written to a temporary beside its target and renamed over it
// only when complete (core/util/atomic_file.h): a failed render or
// merge never replaces an earlier output with a partial one.
//
// Thread safety: TiledExrWriter::WriteTile is thread-safe; everything else is
// thread-compatible.
#ifndef VOX_RENDER_EXR_H_
#define VOX_RENDER_EXR_H_

#include <OpenEXR/ImfForward.h>

#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "core/util/status.h"
#include "render/tiles.h"

namespace vox {

enum ChannelId {
  kChR,
  kChG,
  kChB,
  kChA,
  kChZ,
  kChNx,
  kChNy,
  kChNz,
  kChVi,
  kChVj,
  kChVk,
  kChPx,
  kChPy,
  kChPz,
  kChDist,
  kNumChannels
};
const char* ChannelName(int c);

struct ImageLayers {
  bool normal = false;
  bool voxel = false;
  bool position = false;     // P.X P.Y P.Z
  bool distance = false;     // distance (along the ray)
  bool float_color = false;  // R G B A written as FLOAT; else HALF
  bool Has(int c) const {
    if (c >= kChNx && c <= kChNz) return normal;
    if (c >= kChVi && c <= kChVk) return voxel;
    if (c >= kChPx && c <= kChPz) return position;
    if (c == kChDist) return distance;
    return true;
  }
  // The channels of layers besides R G B A Z.
  int ExtraChannels() const {
    return (normal ? 3 : 0) + (voxel ? 3 : 0) + (position ? 3 : 0) + (distance ? 1 : 0);
  }
};

// One tile's pixels, per channel, row-major with stride `size`.
struct TileBuffer {
  int size = 0;
  std::vector<float> ch[kNumChannels];
  void Allocate(int tile_size, const ImageLayers& layers);
  float* at(int c, int x, int y) { return &ch[c][size_t(y) * size + x]; }
};

using ExrAttributes = std::map<std::string, std::string>;

// How tiles are compressed. kZip is zlib at its fastest level (a few percent
// larger than its default level, at about half the time); kNone suits parts
// that vox-merge recompresses. docs/performance.md has the EXR write's share.
enum class ExrCompression { kZip, kZips, kPiz, kRle, kNone };
// "zip", "zips", "piz", "rle", "none".
StatusOr<ExrCompression> ParseExrCompression(const std::string& name);
const char* ExrCompressionName(ExrCompression c);

// Sizes OpenEXR's global thread pool: it compresses or decompresses the tiles
// of one call in parallel (previews and ReadExr read several per call); a
// call of one tile only moves its work to a pool thread and back, so
// RenderFrame, which writes a tile per call, runs with none. 0 or less: none.
void SetExrThreads(int threads);

class AtomicFile;
class OutputGroup;
struct ExrCameraAttributes;

class TiledExrWriter {
 public:
  // Starts `path` (tiles of `tile` pixels compressed as `compression`,
  // random tile order) with the given string attributes and, given a
  // `camera`, OpenEXR's standard camera attributes (render/camera.h), and
  // reserves renderTimeSeconds and vox:timings for Finish. The file is
  // written to a temporary beside `path`.
  static StatusOr<std::unique_ptr<TiledExrWriter>> Create(
      const std::string& path, int width, int height, int tile, const ImageLayers& layers,
      const ExrAttributes& attrs, ExrCompression compression = ExrCompression::kZip,
      const ExrCameraAttributes* camera = nullptr);
  ~TiledExrWriter();
  // Writes one tile; thread-safe (HALF channels are converted from the
  // buffer's floats, rounding to nearest, before the writer's lock).
  Status WriteTile(const TileRect& rect, const TileBuffer& buf);
  // Finishes the file (tiles not written are left missing: a partial image),
  // records the timings (JSON, at most 1000 bytes) and renames it to `path`;
  // given a `group`, leaves it in its temporary and adds it to the group,
  // published with the run's other outputs (core/util/atomic_file.h).
  Status Finish(double render_seconds, const std::string& timings_json,
                OutputGroup* group = nullptr);
  // Finish without timings.
  Status Close() { return Finish(0.0, ""); }
  // Drops the temporary; an earlier file at `path` stays as it was.
  void Abandon();

 private:
  TiledExrWriter() = default;
  std::string path_;
  std::unique_ptr<AtomicFile> out_;
  ImageLayers layers_;
  std::mutex mu_;
  std::unique_ptr<Imf::OStream> stream_;  // the temporary, outlives file_
  std::unique_ptr<Imf::TiledOutputFile> file_;
  Status failed_;  // the first failed WriteTile: the file is unusable after it
};

// Writes renderTimeSeconds and vox:timings (JSON, at most 1000 bytes) into
// the reserved header slots of a closed file written by TiledExrWriter,
// found by walking the header's attributes (any header size).
Status PatchTimings(const std::string& path, double render_seconds,
                    const std::string& timings_json);

// Header of an EXR written by vox.
struct ExrInfo {
  int width = 0, height = 0, tile = 0;
  std::vector<std::string> channels;
  bool float_color = true;      // R is FLOAT (false: HALF)
  std::string compression;      // OpenEXR's name of the tiles' compression
  ExrAttributes attrs;          // string attributes
  double render_seconds = 0.0;  // renderTimeSeconds, 0 when absent
  bool complete = false;
};
StatusOr<ExrInfo> ReadExrInfo(const std::string& path);

// A whole image in memory, for tests and small files: channel name -> pixels
// (row-major, width x height).
struct ExrImage {
  ExrInfo info;
  std::map<std::string, std::vector<float>> pixels;
};
StatusOr<ExrImage> ReadExr(const std::string& path);

// Reads every tile of `path` (one channel, a row of tiles at a time: memory
// of a row of tiles, whatever the image size): an error names the file when
// a tile is missing or does not decode (a truncated or damaged file).
Status VerifyExrTiles(const std::string& path);

// The background behind pixel (x, y) (whole pixel coordinates from the
// top-left), linear RGB, for composing a premultiplied image over it.
using PreviewBackground = std::function<void(int x, int y, float rgb[3])>;

// Writes an 8-bit sRGB PNG of the R, G, B channels of a complete tiled EXR,
// one row of tiles at a time (bounded memory), atomically. Given a
// `background`, each pixel is composed over it: RGB + (1 - A) background.
// Given a `group`, the finished PNG is added to it instead of published, and
// the EXR is read from `exr_read_path` (its temporary, not yet published)
// when not empty.
Status WritePngPreview(const std::string& exr_path, const std::string& png_path,
                       const PreviewBackground& background = nullptr,
                       OutputGroup* group = nullptr, const std::string& exr_read_path = "");

}  // namespace vox

#endif  // VOX_RENDER_EXR_H_
