#include "render/merge.h"

#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfTiledInputFile.h>

#include <algorithm>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>

#include "render/camera.h"
#include "render/exr.h"
#include "render/frame.h"
#include "render/tiles.h"
#include "core/util/atomic_file.h"
#include "core/util/path_identity.h"

namespace vox {

namespace {

// Reads each part's header: its info and its vox:part.
Status ReadParts(const std::vector<std::string>& parts, std::vector<ExrInfo>* infos,
                 std::vector<PartSpec>* specs) {
  for (const std::string& p : parts) {
    VOX_ASSIGN_OR_RETURN(ExrInfo info, ReadExrInfo(p));
    auto it = info.attrs.find("vox:part");
    if (it == info.attrs.end())
      return InvalidArgumentError(p + ": not a vox-render output (no vox:part attribute)");
    auto spec = ParsePartSpec(it->second);
    if (!spec.ok())
      return InvalidArgumentError(p + ": bad vox:part attribute '" + it->second + "'");
    if (info.attrs["vox:tileOrder"] != "morton")
      return UnsupportedError(p + ": unknown tile order '" + info.attrs["vox:tileOrder"] + "'");
    infos->push_back(std::move(info));
    specs->push_back(*spec);
  }
  return OkStatus();
}

// Everything that must agree, compared with the first part.
Status CheckPartsBelongTogether(const std::vector<std::string>& parts,
                                const std::vector<ExrInfo>& infos,
                                const std::vector<PartSpec>& specs) {
  const ExrInfo& ref = infos[0];
  for (size_t i = 1; i < parts.size(); ++i) {
    const ExrInfo& o = infos[i];
    auto differ = [&](const std::string& what, const std::string& a, const std::string& b) {
      return InvalidArgumentError(parts[i] + " does not belong with " + parts[0] + ": " + what +
                                  " differs (" + b + " vs " + a + ")");
    };
    if (o.width != ref.width || o.height != ref.height)
      return differ("image size", std::to_string(ref.width) + "x" + std::to_string(ref.height),
                    std::to_string(o.width) + "x" + std::to_string(o.height));
    if (o.tile != ref.tile)
      return differ("tile size", std::to_string(ref.tile), std::to_string(o.tile));
    if (o.channels != ref.channels) return differ("channel list", "", "");
    if (o.float_color != ref.float_color)
      return differ("colour pixel type", ref.float_color ? "float" : "half",
                    o.float_color ? "float" : "half");
    {
      auto a = ref.attrs.find("vox:storeId"), b = o.attrs.find("vox:storeId");
      std::string va = a == ref.attrs.end() ? "<none>" : a->second;
      std::string vb = b == o.attrs.end() ? "<none>" : b->second;
      if (va != vb)
        return InvalidArgumentError(parts[i] + " and " + parts[0] +
                                    " were rendered from different stores (store_id " + vb +
                                    " vs " + va + "; was the store re-ingested between parts?)");
    }
    for (const char* key :
         {"vox:camera", "vox:scene", "vox:split", "vox:store", "vox:passes", "vox:lod"}) {
      auto a = ref.attrs.find(key), b = o.attrs.find(key);
      std::string va = a == ref.attrs.end() ? "<none>" : a->second;
      std::string vb = b == o.attrs.end() ? "<none>" : b->second;
      if (va != vb) return differ(key, va, vb);
    }
    if (specs[i].count != specs[0].count)
      return differ("part count", std::to_string(specs[0].count), std::to_string(specs[i].count));
  }
  return OkStatus();
}

// Which of `parts` is part k, for k = 1..N; refuses a part given twice or missing.
StatusOr<std::map<int, size_t>> IndexParts(const std::vector<std::string>& parts,
                                           const std::vector<PartSpec>& specs) {
  const int n = specs[0].count;
  std::map<int, size_t> by_index;
  for (size_t i = 0; i < parts.size(); ++i) {
    auto [it, inserted] = by_index.emplace(specs[i].index, i);
    if (!inserted)
      return InvalidArgumentError("parts overlap: " + parts[it->second] + " and " + parts[i] +
                                  " are both part " + specs[i].ToString());
  }
  for (int k = 1; k <= n; ++k)
    if (!by_index.count(k))
      return InvalidArgumentError("part " + std::to_string(k) + "/" + std::to_string(n) +
                                  " is missing (" + std::to_string(parts.size()) + " of " +
                                  std::to_string(n) + " parts given)");
  return by_index;
}

// Copies the tiles of `path`, part `spec` of `layout`, into `writer`
// through `buf`; counts them in *tiles.
Status CopyPartTiles(const std::string& path, const PartSpec& spec, const TileLayout& layout,
                     const ImageLayers& layers, TileBuffer& buf, TiledExrWriter& writer,
                     int64_t* tiles) {
  int64_t begin = 0, end = 0;
  layout.PartRange(spec, &begin, &end);
  try {
    Imf::TiledInputFile in(path.c_str());
    Imf::FrameBuffer fb;
    for (int c = 0; c < kNumChannels; ++c)
      if (layers.Has(c))
        fb.insert(ChannelName(c),
                  Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(buf.ch[c].data()), sizeof(float),
                             sizeof(float) * size_t(buf.size), 1, 1, 0.0, true, true));
    in.setFrameBuffer(fb);
    for (int64_t t = begin; t < end; ++t) {
      const TileRect& r = layout.order()[size_t(t)];
      try {
        in.readTile(r.tx, r.ty);
      } catch (const std::exception& e) {
        return CorruptionError(path + ": part " + spec.ToString() + " lacks tile (" +
                               std::to_string(r.tx) + ", " + std::to_string(r.ty) +
                               "); did its render finish? (" + e.what() + ")");
      }
      VOX_RETURN_IF_ERROR(writer.WriteTile(r, buf));
      ++*tiles;
    }
  } catch (const std::exception& e) {
    return IoError(path + ": cannot read: " + e.what());
  }
  return OkStatus();
}

}  // namespace

Status MergeParts(const std::vector<std::string>& parts, const std::string& out_path,
                  MergeResult* result, const std::string& preview_path) {
  if (parts.empty()) return InvalidArgumentError("vox-merge: no part files given");
  // Before reading anything: no output may be one of the parts (by device
  // and inode, so ./p1.exr and p1.exr or a hard link are caught) or the
  // other output, and their directories must be writable.
  for (const std::string& p : parts)
    if (p == out_path)
      return InvalidArgumentError("output " + out_path + " is the part " + p +
                                  "; writing it would destroy that part");
  VOX_RETURN_IF_ERROR(CheckOutputPath(out_path));
  VOX_RETURN_IF_ERROR(CheckExtension("-o", out_path, ".exr"));
  if (!preview_path.empty()) {
    VOX_RETURN_IF_ERROR(CheckOutputPath(preview_path));
    VOX_RETURN_IF_ERROR(CheckExtension("--preview", preview_path, ".png"));
  }
  std::vector<NamedPath> inputs;
  for (const std::string& p : parts) inputs.push_back({"part", p});
  VOX_RETURN_IF_ERROR(
      CheckDistinctPaths(inputs, {{"-o", out_path}, {"--preview", preview_path}}));
  std::vector<ExrInfo> infos;
  std::vector<PartSpec> specs;
  VOX_RETURN_IF_ERROR(ReadParts(parts, &infos, &specs));
  VOX_RETURN_IF_ERROR(CheckPartsBelongTogether(parts, infos, specs));
  using PartIndex = std::map<int, size_t>;  // part k -> its place in `parts`
  VOX_ASSIGN_OR_RETURN(PartIndex by_index, IndexParts(parts, specs));
  const ExrInfo& ref = infos[0];
  const int n = specs[0].count;

  ImageLayers layers;
  layers.float_color = ref.float_color;
  for (const std::string& c : ref.channels) {
    if (c == ChannelName(kChNx)) layers.normal = true;
    if (c == ChannelName(kChVi)) layers.voxel = true;
    if (c == ChannelName(kChPx)) layers.position = true;
    if (c == ChannelName(kChDist)) layers.distance = true;
  }
  // The parts' vox:camera comes along, and with it the standard camera
  // attributes (render/exr.h), computed again from it.
  std::optional<ExrCameraAttributes> camera_attrs;
  if (auto json = ref.attrs.find("vox:camera"); json != ref.attrs.end())
    if (StatusOr<Camera> cam = ParseCamera(json->second, "vox:camera"); cam.ok())
      camera_attrs = StandardCameraAttributes(*cam);  // else not a vox camera: none
  ExrAttributes attrs = ref.attrs;
  attrs.erase("vox:timings");
  attrs["vox:part"] = "1/1";
  attrs["vox:mergedFrom"] = std::to_string(n) + " parts";
  if (ref.tile > kMaxTileSize)
    return UnsupportedError(parts[0] + ": tile size " + std::to_string(ref.tile) +
                            " is larger than vox writes (" + std::to_string(kMaxTileSize) + ")");
  VOX_RETURN_IF_ERROR(CheckTileCount(ref.width, ref.height, ref.tile).WithContext(parts[0]));
  const TileLayout layout(ref.width, ref.height, ref.tile);
  VOX_ASSIGN_OR_RETURN(auto writer,
                       TiledExrWriter::Create(out_path, ref.width, ref.height, ref.tile, layers,
                                              attrs, ExrCompression::kZip,
                                              camera_attrs ? &*camera_attrs : nullptr));
  TileBuffer buf;
  buf.Allocate(ref.tile, layers);
  MergeResult res;
  res.parts = n;
  for (int k = 1; k <= n; ++k) {
    const size_t i = by_index[k];
    res.sum_render_seconds += infos[i].render_seconds;
    res.max_render_seconds = std::max(res.max_render_seconds, infos[i].render_seconds);
    VOX_RETURN_IF_ERROR(
        CopyPartTiles(parts[i], specs[i], layout, layers, buf, *writer, &res.tiles));
  }
  nlohmann::json timings{{"parts", n},
                         {"sum_render_seconds", res.sum_render_seconds},
                         {"max_render_seconds", res.max_render_seconds}};
  OutputGroup outputs;
  VOX_RETURN_IF_ERROR(writer->Finish(res.max_render_seconds, timings.dump(), &outputs));
  if (!preview_path.empty())
    VOX_RETURN_IF_ERROR(
        WritePngPreview(out_path, preview_path, nullptr, &outputs, outputs.TempOf(out_path)));
  VOX_RETURN_IF_ERROR(outputs.Commit());
  if (result) *result = res;
  return OkStatus();
}

}  // namespace vox
