// Frame sequences: frame ranges, printf patterns and turntable
// cameras as functions; then vox-render end to end: a --cam array renders
// each frame as a single run with that camera would (pixel for pixel), a
// turntable's cameras keep their distance and elevation, --frames renders
// exactly its frames, bad patterns are refused before any work, the brick
// cache is kept between frames, and a signal keeps the finished frames.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <glm/geometric.hpp>
#include <nlohmann/json.hpp>
#include <thread>

#include "render/camera.h"
#include "render/exr.h"
#include "render/frame_sequence.h"
#include "tests/common/run_command.h"
#include "tests/common/spawn.h"
#include "tests/render/store_suite.h"
#include "tests/render/store_util.h"

namespace vox {
namespace {

namespace fs = std::filesystem;

bool Has(const std::string& s, const std::string& part) { return s.find(part) != std::string::npos; }

TEST(FrameRangeTest, ParsesRangesAndSingleFrames) {
  auto r = ParseFrameRange("3-7");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->first, 3);
  EXPECT_EQ(r->last, 7);
  r = ParseFrameRange("12");
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->first, 12);
  EXPECT_EQ(r->last, 12);
  for (const char* bad : {"", "0", "0-3", "5-4", "-3", "3-", "a-b", "1-2-3", "+2", "2000000"})
    EXPECT_FALSE(ParseFrameRange(bad).ok()) << bad;
  FrameRange range{2, 5};
  EXPECT_FALSE(FramesToRender(4, &range).ok());
  EXPECT_TRUE(FramesToRender(5, &range).ok());
  auto all = FramesToRender(36, nullptr);
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->first, 1);
  EXPECT_EQ(all->last, 36);
}

TEST(FramePatternTest, ExpandsOneConversionAndLeavesPlainNamesAlone) {
  EXPECT_EQ(ExpandFramePattern("out.%04d.exr", 7), "out.0007.exr");
  EXPECT_EQ(ExpandFramePattern("out.%d.exr", 12), "out.12.exr");
  EXPECT_EQ(ExpandFramePattern("dir%%/f%3d.exr", 5), "dir%/f  5.exr");
  EXPECT_EQ(ExpandFramePattern("100%.exr", 5), "100%.exr");     // plain: as it is
  EXPECT_EQ(ExpandFramePattern("a%%b.exr", 5), "a%%b.exr");     // plain: no %d
  EXPECT_EQ(*IsFramePattern("-o", "out.%04d.exr"), true);
  EXPECT_EQ(*IsFramePattern("-o", "out.exr"), false);
  EXPECT_EQ(*IsFramePattern("-o", "100%.exr"), false);
  auto two = IsFramePattern("-o", "a%d.%d.exr");
  ASSERT_FALSE(two.ok());
  EXPECT_TRUE(Has(two.status().message(), "one %d")) << two.status().message();
  auto stray = IsFramePattern("--stats", "a%s.%d.json");
  ASSERT_FALSE(stray.ok());
  EXPECT_TRUE(Has(stray.status().message(), "--stats")) << stray.status().message();
}

// Distance to the pivot, elevation above the plane across the axis and
// azimuth in that plane (from `front`, towards axis x front), in degrees.
struct Orbit {
  double distance, elevation, azimuth;
};
Orbit OrbitOf(const Camera& c, const glm::dvec3& pivot, const glm::dvec3& axis,
              const glm::dvec3& front) {
  const glm::dvec3 d = c.position - pivot;
  const double dist = glm::length(d);
  const double up = glm::dot(d, axis);
  const glm::dvec3 flat = d - up * axis;
  const glm::dvec3 side = glm::cross(axis, front);
  double az = std::atan2(glm::dot(flat, side), glm::dot(flat, front)) * 180.0 / M_PI;
  if (az < 0) az += 360.0;
  return {dist, std::asin(up / dist) * 180.0 / M_PI, az};
}

TEST(TurntableTest, CamerasKeepDistanceAndElevationInEqualAzimuthSteps) {
  auto base = ParseCamera(
      R"({"position":[3,4,10], "look_at":[1,0,0], "up":[0,1,0], "fov_deg":40, "width":32, "height":24})",
      "cam");
  ASSERT_TRUE(base.ok());
  auto cams = TurntableCameras(*base, 8, glm::dvec3(0.0));
  ASSERT_TRUE(cams.ok()) << cams.status().ToString();
  ASSERT_EQ(cams->size(), 8u);
  EXPECT_EQ((*cams)[0].ToJson(), base->ToJson());  // frame 1 is the camera itself
  const glm::dvec3 pivot(1, 0, 0), axis(0, 1, 0);
  const Orbit o0 = OrbitOf(*base, pivot, axis, glm::dvec3(0, 0, 1));
  for (int i = 0; i < 8; ++i) {
    const Camera& c = (*cams)[size_t(i)];
    const Orbit o = OrbitOf(c, pivot, axis, glm::dvec3(0, 0, 1));
    EXPECT_NEAR(o.distance, o0.distance, 1e-9) << i;
    EXPECT_NEAR(o.elevation, o0.elevation, 1e-9) << i;
    EXPECT_NEAR(std::fmod(o.azimuth - o0.azimuth + 360.0, 360.0), 45.0 * i, 1e-9) << i;
    EXPECT_NEAR(glm::length(c.look_at - pivot), 0.0, 1e-12) << i;
  }
  // A camera_to_world camera turns about the world axis nearest its up
  // (here Z), through the point of its view axis nearest the centre; its
  // roll is kept.
  auto matrix = ParseCamera(
      R"({"camera_to_world":[1,0,0,0, 0,0,-1,-10, 0,1,0,2, 0,0,0,1], "fov_deg":40, "width":32, "height":24})",
      "cam");
  ASSERT_TRUE(matrix.ok()) << matrix.status().ToString();
  auto turned = TurntableCameras(*matrix, 4, glm::dvec3(0.0));
  ASSERT_TRUE(turned.ok()) << turned.status().ToString();
  const glm::dvec3 mp = TurntablePivot(*matrix, glm::dvec3(0.0));
  EXPECT_NEAR(glm::length(mp - glm::dvec3(0, 0, 2)), 0.0, 1e-12);
  for (int i = 0; i < 4; ++i) {
    const Camera& c = (*turned)[size_t(i)];
    const Orbit o = OrbitOf(c, mp, glm::dvec3(0, 0, 1), glm::dvec3(0, -1, 0));
    EXPECT_NEAR(o.distance, 10.0, 1e-9) << i;
    EXPECT_NEAR(o.elevation, 0.0, 1e-9) << i;
    EXPECT_NEAR(o.azimuth, 90.0 * i, 1e-9) << i;
    EXPECT_NEAR(glm::dot(c.forward(), glm::normalize(mp - c.position)), 1.0, 1e-12) << i;
    EXPECT_NEAR(glm::dot(c.true_up(), glm::dvec3(0, 0, 1)), 1.0, 1e-12) << i;
  }
  EXPECT_FALSE(TurntableCameras(*base, 0, glm::dvec3(0.0)).ok());
}

TEST(CameraArrayTest, ParsesObjectsAndArraysNamingTheBadElement) {
  const char one[] = R"({"position":[0,0,10], "look_at":[0,0,0], "fov_deg":40, "width":8, "height":8})";
  auto single = ParseCameras(one, "c.json");
  ASSERT_TRUE(single.ok());
  EXPECT_EQ(single->size(), 1u);
  auto list = ParseCameras(std::string("[") + one + "," + one + "]", "c.json");
  ASSERT_TRUE(list.ok());
  EXPECT_EQ(list->size(), 2u);
  auto bad = ParseCameras(std::string("[") + one + R"(, {"position":[0,0,1]}])", "c.json");
  ASSERT_FALSE(bad.ok());
  EXPECT_TRUE(Has(bad.status().message(), "c.json[1]")) << bad.status().message();
  EXPECT_FALSE(ParseCameras("[]", "c.json").ok());
  EXPECT_FALSE(ParseCameras("[1]", "c.json").ok());
}

class SequenceCliTest : public testing::SphereShellStoreSuite {
 protected:
  static testing::CommandResult Render(const std::string& args) {
    return testing::RunCommand(std::string(VOX_RENDER_BIN) + " " + Path("store") +
                               " --threads 2 --tile-size 16 " + args);
  }
  static nlohmann::json Json(const std::string& path) {
    std::ifstream in(path);
    return nlohmann::json::parse(in);
  }
  // The files of the test directory whose names start with `prefix`.
  static std::vector<std::string> Files(const std::string& prefix) {
    std::vector<std::string> v;
    for (const auto& e : fs::directory_iterator(*dir_)) {
      const std::string n = e.path().filename().string();
      if (n.compare(0, prefix.size(), prefix) == 0) v.push_back(n);
    }
    std::sort(v.begin(), v.end());
    return v;
  }
  static void ExpectSamePixels(const std::string& a, const std::string& b) {
    auto x = ReadExr(a), y = ReadExr(b);
    ASSERT_TRUE(x.ok() && y.ok()) << a << " " << b;
    ASSERT_EQ(x->pixels.size(), y->pixels.size());
    for (const auto& [name, pixels] : x->pixels) {
      ASSERT_EQ(pixels.size(), y->pixels[name].size()) << name;
      EXPECT_EQ(std::memcmp(pixels.data(), y->pixels[name].data(), pixels.size() * 4), 0)
          << a << " and " << b << " differ in " << name;
    }
    EXPECT_EQ(x->info.attrs["vox:camera"], y->info.attrs["vox:camera"]);
  }
};

const char kCamA[] =
    R"({"position":[0,3,20], "look_at":[0,0,0], "fov_deg":40, "width":48, "height":32})";
const char kCamB[] =
    R"({"position":[14,-4,12], "look_at":[1,0,0], "fov_deg":30, "width":40, "height":40})";
const char kCamC[] =
    R"({"camera_to_world":[0,0,1,18, 0,1,0,0, -1,0,0,0, 0,0,0,1], "fov_deg":45, "width":32, "height":48})";

// Every frame's size, tiles and room on disk are checked before the first
// frame is rendered: a bad third camera leaves no frame published.
TEST_F(SequenceCliTest, ABadFrameInAnArrayIsFoundBeforeTheFirstFrame) {
  const std::string huge =
      R"({"position":[0,3,20], "look_at":[0,0,0], "fov_deg":40, "width":100000, "height":100000})";
  const std::string cams =
      Write("badsize.json", std::string("[") + kCamA + ",\n" + kCamB + ",\n" + huge + "]");
  auto r = Render("--cam " + cams + " -o " + Path("bad.%02d.exr"));
  EXPECT_EQ(r.code, 1) << r.output;
  EXPECT_TRUE(Has(r.output, "frame 3") && Has(r.output, "100000x100000")) << r.output;
  EXPECT_FALSE(Has(r.output, "frame 1/3")) << "work began: " << r.output;
  EXPECT_EQ(Files("bad."), std::vector<std::string>{});
}

TEST_F(SequenceCliTest, CameraArrayRendersEachFrameAsASingleRunWould) {
  const std::string cams =
      Write("cams.json", std::string("[") + kCamA + ",\n" + kCamB + ",\n" + kCamC + "]");
  auto r = Render("--cam " + cams + " -o " + Path("arr.%02d.exr") + " --preview " +
                  Path("arr.%02d.png") + " --stats " + Path("arr.%02d.json") +
                  " --layers normal,distance --save-cam " + Path("arr-used.json"));
  ASSERT_EQ(r.code, 0) << r.output;
  for (const char* f : {"frame 1/3", "frame 2/3", "frame 3/3"}) EXPECT_TRUE(Has(r.output, f)) << r.output;
  EXPECT_EQ(Files("arr."), (std::vector<std::string>{"arr.01.exr", "arr.01.json", "arr.01.png",
                                                     "arr.02.exr", "arr.02.json", "arr.02.png",
                                                     "arr.03.exr", "arr.03.json", "arr.03.png"}));
  const char* singles[] = {kCamA, kCamB, kCamC};
  for (int i = 0; i < 3; ++i) {
    const std::string n = std::to_string(i + 1);
    const std::string cam = Write("single" + n + ".json", singles[i]);
    auto s = Render("--quiet --layers normal,distance --cam " + cam + " -o " + Path("single" + n + ".exr"));
    ASSERT_EQ(s.code, 0) << s.output;
    ExpectSamePixels(Path("arr.0" + n + ".exr"), Path("single" + n + ".exr"));
    const nlohmann::json stats = Json(Path("arr.0" + n + ".json"));
    EXPECT_EQ(stats["frame"]["number"], i + 1);
    EXPECT_EQ(stats["frame"]["count"], 3);
    EXPECT_EQ(stats["camera"]["source"]["index"], i);
    EXPECT_EQ(stats["camera"]["source"]["camera"], cams);
  }
  // --save-cam with a plain name: the array of the cameras used, which
  // renders the same frames again.
  const nlohmann::json used = Json(Path("arr-used.json"));
  ASSERT_TRUE(used.is_array());
  ASSERT_EQ(used.size(), 3u);
  EXPECT_TRUE(used[2].contains("camera_to_world"));
  r = Render("--quiet --layers normal,distance --cam " + Path("arr-used.json") + " -o " +
             Path("again.%d.exr") + " --frames 3");
  ASSERT_EQ(r.code, 0) << r.output;
  ExpectSamePixels(Path("again.3.exr"), Path("single3.exr"));
}

TEST_F(SequenceCliTest, TurntableCamerasAndFrameRanges) {
  // --view's camera turned in 6 steps: frames 2 to 4 only, numbered from
  // the pattern, with their cameras saved per frame.
  auto r = Render("--quiet --size 40x30 --view 30,20 --turntable 6 --frames 2-4 -o " +
                  Path("tt.%04d.exr") + " --stats " + Path("tt.%04d.json") + " --save-cam " +
                  Path("ttcam.%d.json"));
  ASSERT_EQ(r.code, 0) << r.output;
  EXPECT_EQ(r.output, "");
  EXPECT_EQ(Files("tt."), (std::vector<std::string>{"tt.0002.exr", "tt.0002.json", "tt.0003.exr",
                                                    "tt.0003.json", "tt.0004.exr",
                                                    "tt.0004.json"}));
  EXPECT_EQ(Files("ttcam."),
            (std::vector<std::string>{"ttcam.2.json", "ttcam.3.json", "ttcam.4.json"}));
  // Frame 1 of the same sequence is --view's camera: the others are it
  // turned by 60 degrees a frame about up, through the box's centre.
  r = Render("--quiet --size 40x30 --view 30,20 -o " + Path("view.exr") + " --save-cam " +
             Path("viewcam.json"));
  ASSERT_EQ(r.code, 0) << r.output;
  auto first = LoadCamera(Path("viewcam.json"));
  ASSERT_TRUE(first.ok());
  const glm::dvec3 pivot = first->look_at, axis(0, 1, 0), front(0, 0, 1);
  const Orbit o1 = OrbitOf(*first, pivot, axis, front);
  EXPECT_NEAR(o1.azimuth, 30.0, 1e-9);
  EXPECT_NEAR(o1.elevation, 20.0, 1e-9);
  for (int n = 2; n <= 4; ++n) {
    auto cam = LoadCamera(Path("ttcam." + std::to_string(n) + ".json"));
    ASSERT_TRUE(cam.ok()) << cam.status().ToString();
    const Orbit o = OrbitOf(*cam, pivot, axis, front);
    EXPECT_NEAR(o.distance, o1.distance, 1e-9 * o1.distance) << n;
    EXPECT_NEAR(o.elevation, 20.0, 1e-9) << n;
    EXPECT_NEAR(o.azimuth, 30.0 + 60.0 * (n - 1), 1e-9) << n;
    const nlohmann::json stats = Json(Path("tt.000" + std::to_string(n) + ".json"));
    EXPECT_EQ(stats["frame"]["number"], n);
    EXPECT_EQ(stats["frame"]["first"], 2);
    EXPECT_EQ(stats["frame"]["last"], 4);
    EXPECT_EQ(stats["camera"]["source"]["turntable"]["frames"], 6);
    EXPECT_DOUBLE_EQ(stats["camera"]["source"]["turntable"]["turn_deg"].get<double>(), 60.0 * (n - 1));
    // The frame is the one a single run with its saved camera renders.
    auto s = Render("--quiet --cam " + Path("ttcam." + std::to_string(n) + ".json") + " -o " +
                    Path("ttsingle.exr"));
    ASSERT_EQ(s.code, 0) << s.output;
    ExpectSamePixels(Path("tt.000" + std::to_string(n) + ".exr"), Path("ttsingle.exr"));
  }
  // One frame of a sequence may take a plain name only when the sequence
  // has one frame.
  r = Render("--quiet --turntable 1 -o " + Path("one.exr") + " --size 16x16");
  EXPECT_EQ(r.code, 0) << r.output;
  EXPECT_TRUE(fs::exists(Path("one.exr")));
}

TEST_F(SequenceCliTest, BadPatternsAreRefusedBeforeAnyWork) {
  const std::string cam = Write("c1.json", kCamA);
  struct Case {
    std::string args, expect;
    int code = 1;  // 2: a bad flag value, refused as the command line is read
  } cases[] = {
      {"--turntable 3 -o " + Path("nopat.exr"), "give a frame pattern such as"},
      {"--turntable 3 -o " + Path("p.%d.exr") + " --stats " + Path("nopat.json"),
       "--stats " + Path("nopat.json")},
      // Two patterns naming the same files.
      {"--turntable 3 -o " + Path("p.%d.exr") + " --stats " + Path("p.%d.exr"), "same file"},
      {"--turntable 12 -o " + Path("p.%02d.exr") + " --stats " + Path("p.%d.exr") + " --frames 10-12",
       "same file"},
      // A pattern whose frame 1 is the camera file.
      {"--cam " + cam + " --turntable 2 -o " + Path("p.%d.exr") + " --stats " + Path("c%d.json"),
       "writing it would destroy that input"},
      {"--turntable 3 -o " + Path("p.%d.%d.exr"), "one %d"},
      {"--turntable 3 --frames 2-4 -o " + Path("p.%d.exr"), "the sequence has 3 frames"},
      {"--cam " + Write("two.json", std::string("[") + kCamA + "," + kCamB + "]") +
           " --turntable 3 -o " + Path("p.%d.exr"),
       "--turntable turns one camera"},
      {"--frames 0 -o " + Path("p.%d.exr"), "--frames '0'", 2},
  };
  const std::string cam_bytes = testing::RunCommand("cat " + cam).output;
  for (const Case& c : cases) {
    auto r = Render(c.args);
    EXPECT_EQ(r.code, c.code) << c.args << "\n" << r.output;
    EXPECT_TRUE(Has(r.output, c.expect)) << c.args << "\n" << r.output;
    EXPECT_FALSE(Has(r.output, "vox-render: memory")) << "work began: " << r.output;
  }
  EXPECT_EQ(Files("p."), std::vector<std::string>{});
  EXPECT_EQ(Files("nopat"), std::vector<std::string>{});
  EXPECT_EQ(testing::RunCommand("cat " + cam).output, cam_bytes);
  EXPECT_FALSE(fs::exists(Path("c2.json")));
}

TEST_F(SequenceCliTest, TheBrickCacheIsKeptBetweenFrames) {
  // The same camera twice: the second frame finds every brick in the cache
  // of the one opened store and reads none.
  const std::string cams = Write("same.json", std::string("[") + kCamA + "," + kCamA + "]");
  auto r = Render("--quiet --cam " + cams + " -o " + Path("same.%d.exr") + " --stats " +
                  Path("same.%d.json"));
  ASSERT_EQ(r.code, 0) << r.output;
  const nlohmann::json a = Json(Path("same.1.json")), b = Json(Path("same.2.json"));
  EXPECT_GT(a["cache"]["misses"].get<int64_t>(), 0);
  EXPECT_GT(a["io"]["brick_bytes_read"].get<int64_t>(), 0);
  EXPECT_EQ(b["cache"]["misses"].get<int64_t>(), 0);
  EXPECT_EQ(b["io"]["brick_bytes_read"].get<int64_t>(), 0);
  EXPECT_GT(b["cache"]["hits"].get<int64_t>() + b["rays"]["primary"].get<int64_t>(), 0);
  EXPECT_GT(a["timings"]["open_seconds"].get<double>(), 0.0);
  EXPECT_EQ(b["timings"]["open_seconds"].get<double>(), 0.0);
  ExpectSamePixels(Path("same.1.exr"), Path("same.2.exr"));
  // A turntable's second frame, 10 degrees on, reads fewer bricks than the
  // first, which started with an empty cache.
  r = Render("--quiet --cam " + Write("tt36.json", kCamA) + " --turntable 36 --frames 1-2 -o " +
             Path("t36.%d.exr") + " --stats " + Path("t36.%d.json"));
  ASSERT_EQ(r.code, 0) << r.output;
  const nlohmann::json t1 = Json(Path("t36.1.json")), t2 = Json(Path("t36.2.json"));
  EXPECT_LT(t2["cache"]["misses"].get<int64_t>(), t1["cache"]["misses"].get<int64_t>());
}

// A signal during frame 2 stops the run: frame 1's files stay as they were
// published, frame 2's temporaries are removed, frame 3 never starts.
TEST_F(SequenceCliTest, ASignalKeepsTheFinishedFrames) {
  const pid_t pid = testing::SpawnInGroup(
      {VOX_RENDER_BIN, Path("store"), "--size", "1500x1500", "--threads", "1", "--turntable", "3",
       "-o", Path("sig.%d.exr"), "--stats", Path("sig.%d.json")});
  ASSERT_GT(pid, 0);
  bool published = false;
  for (int i = 0; i < 12000 && !published; ++i) {
    published = fs::exists(Path("sig.1.json"));
    if (!published) std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  ASSERT_TRUE(published) << "frame 1 was not published";
  kill(pid, SIGTERM);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 128 + SIGTERM);
  EXPECT_EQ(testing::TempEntries(dir_->string()), std::vector<std::string>{});
  auto first = ReadExr(Path("sig.1.exr"));
  EXPECT_TRUE(first.ok()) << first.status().ToString();
  EXPECT_FALSE(fs::exists(Path("sig.3.exr")));
  EXPECT_FALSE(fs::exists(Path("sig.3.json")));
}

}  // namespace
}  // namespace vox
