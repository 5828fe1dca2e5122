// The command line of each vox tool, end to end: --flag=value
// works, --version prints the version line, --help groups the options by
// topic, a bad command line prints one line and a pointer to the help,
// exit 2, and an input that is not there (a store, a file) is a failure of
// the run: exit 1, one message naming it, whichever tool reads it.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <string>
#include <vector>

#include "tests/common/run_command.h"
#include "tools/common/options.h"

namespace vox {
namespace {

struct Tool {
  std::string name, binary;
  std::vector<std::string> groups;  // the help's headings
  std::string value_flag;           // a flag that takes a value
  std::string switch_flag;          // a switch ("" if none)
};

const std::vector<Tool>& Tools() {
  static const std::vector<Tool> tools = {
      {"vox-ingest", VOX_INGEST_BIN,
       {"Input grid", "Store", "Level of detail", "Memory and threads", "Output", "General"},
       "--zstd-level", "--quiet"},
      {"vox-render", VOX_RENDER_BIN,
       {"Camera and scene", "Frame sequences", "Output", "Level of detail", "Memory and I/O",
        "Tracing", "Parallel runs", "General"},
       "--threads", "--quiet"},
      {"vox-probe", VOX_PROBE_BIN,
       {"Source", "Tracing", "Level of detail", "Memory and I/O", "General"}, "--cache-mb",
       "--stats"},
      {"vox-gen", VOX_GEN_BIN, {"Shape and size", "Store", "Run", "General"}, "--size", "--quiet"},
      {"vox-info", VOX_INFO_BIN, {"Verification", "General"}, "--cache-mb", "--verify"},
      {"vox-merge", VOX_MERGE_BIN, {"Output", "General"}, "--preview", "--quiet"},
  };
  return tools;
}

// Standard output and standard error apart.
struct ToolRun {
  int code;
  std::string out, err;
};

ToolRun RunTool(const Tool& t, const std::string& args) {
  const std::string cmd = t.binary + " " + args + " </dev/null";
  // RunCommand folds standard error into standard output: a group keeps one.
  const testing::CommandResult out = testing::RunCommand("{ " + cmd + " 2>/dev/null; }");
  const testing::CommandResult err = testing::RunCommand("{ " + cmd + " 2>&1 >/dev/null; }");
  EXPECT_EQ(out.code, err.code) << cmd;
  return {out.code, out.output, err.output};
}

void ExpectUsageError(const Tool& t, const std::string& args, const std::string& message) {
  const ToolRun r = RunTool(t, args);
  EXPECT_EQ(r.code, 2) << t.name << " " << args << "\n" << r.err;
  EXPECT_EQ(r.err, t.name + ": " + message + "\nsee " + t.name + " --help\n") << args;
  EXPECT_EQ(r.out, "") << args;
}

TEST(ToolCommandLine, VersionPrintsOneLine) {
  for (const Tool& t : Tools()) {
    const ToolRun r = RunTool(t, "--version");
    EXPECT_EQ(r.code, 0) << t.name;
    EXPECT_EQ(r.err, "") << t.name;
    EXPECT_EQ(r.out.rfind(t.name + " ", 0), 0u) << r.out;
    EXPECT_NE(r.out.find(" (git "), std::string::npos) << r.out;
    EXPECT_EQ(r.out.find('\n'), r.out.size() - 1) << r.out;
  }
}

TEST(ToolCommandLine, HelpIsGroupedByTopic) {
  for (const Tool& t : Tools()) {
    for (const char* flag : {"--help", "-h"}) {
      const ToolRun r = RunTool(t, flag);
      EXPECT_EQ(r.code, 0) << t.name;
      EXPECT_EQ(r.err, "") << t.name;
      EXPECT_EQ(r.out.rfind("usage: " + t.name + " ", 0), 0u) << r.out;
      size_t at = 0;
      for (const std::string& group : t.groups) {  // in this order
        const size_t found = r.out.find("\n" + group + ":\n", at);
        EXPECT_NE(found, std::string::npos) << t.name << ": no group " << group << "\n" << r.out;
        if (found != std::string::npos) at = found;
      }
      EXPECT_NE(r.out.find("  " + t.value_flag + " "), std::string::npos) << r.out;
      EXPECT_NE(r.out.find("--version"), std::string::npos) << r.out;
    }
  }
}

TEST(ToolCommandLine, BadCommandLinesPrintOneLineAndExit2) {
  for (const Tool& t : Tools()) {
    ExpectUsageError(t, "--no-such-flag", "unknown option --no-such-flag");
    ExpectUsageError(t, "x --no-such-flag=3 y", "unknown option --no-such-flag");
    ExpectUsageError(t, "x " + t.value_flag, t.value_flag + " needs a value");
    ExpectUsageError(t, "x " + t.switch_flag + "=1",
                     t.switch_flag + " is a switch and takes no value");
  }
}

// The same error class, the same exit code in every tool: an input that does
// not exist, or a directory that is not a store, fails the run (exit 1) with
// a message naming it, and no output appears.
TEST(ToolCommandLine, MissingInputsExit1NamingThem) {
  const std::filesystem::path dir =
      std::filesystem::path(::testing::TempDir()) / ("tool_missing_" + std::to_string(getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir / "empty_dir");
  const std::string out = (dir / "out").string();
  for (const std::string& missing :
       std::vector<std::string>{(dir / "no_such").string(), (dir / "empty_dir").string()}) {
    const std::vector<std::pair<const Tool*, std::string>> runs = {
        {&Tools()[1], missing + " -o " + out + ".exr --size 8x8"},
        {&Tools()[2], missing},
        {&Tools()[2], missing + " --at 0 0 0"},
        {&Tools()[2], missing + " --slice x 0 -o " + out + ".exr"},
        {&Tools()[4], missing},
        {&Tools()[0], "--add-lod " + missing},
    };
    for (const auto& [tool, args] : runs) {
      const ToolRun r = RunTool(*tool, args);
      EXPECT_EQ(r.code, 1) << tool->name << " " << args << "\n" << r.err;
      EXPECT_NE(r.err.find("'" + missing + "'"), std::string::npos) << tool->name << " " << args
                                                                   << "\n" << r.err;
      EXPECT_EQ(r.out, "") << tool->name << " " << args;
    }
  }
  // Files: vox-ingest's inputs (a .vdb, a .npy, a raw array) and vox-merge's parts.
  for (const char* name : {"no_such.vdb", "no_such.npy", "no_such.raw"}) {
    const std::string missing = (dir / name).string();
    const std::string raw =
        std::string(name) == "no_such.raw" ? " --shape 2,2,2 --dtype uint8" : "";
    const ToolRun r = RunTool(Tools()[0], missing + " " + out + raw);
    EXPECT_EQ(r.code, 1) << name << "\n" << r.err;
    EXPECT_NE(r.err.find(missing), std::string::npos) << r.err;
  }
  const std::string part = (dir / "no_such_part.exr").string();
  const ToolRun merge = RunTool(Tools()[5], part + " -o " + out + ".exr");
  EXPECT_EQ(merge.code, 1) << merge.err;
  EXPECT_NE(merge.err.find(part), std::string::npos) << merge.err;
  for (const auto& e : std::filesystem::directory_iterator(dir))
    EXPECT_EQ(e.path().filename(), "empty_dir") << "an output appeared: " << e.path();
  std::filesystem::remove_all(dir);
}

// An empty value is refused naming its flag, in both spellings: "--stats="
// never takes the next argument as its value.
TEST(ToolCommandLine, EmptyValuesAreRefusedNamingTheFlag) {
  const std::pair<std::string, OptionTable> tables[] = {
      {"vox-ingest", IngestOptionTable()},
      {"vox-render", RenderOptionTable()},
      {"vox-probe", ProbeOptionTable()},
  };
  for (const auto& [name, table] : tables) {
    const Tool& t = *std::find_if(Tools().begin(), Tools().end(),
                                  [&](const Tool& x) { return x.name == name; });
    for (const OptionSpec& o : table) {
      if (o.arity != FlagArity::kValue) continue;
      const std::string message =
          std::string(o.name) + ": an empty value; expected " + o.value_name;
      if (std::string(o.name).rfind("--", 0) == 0)
        ExpectUsageError(t, std::string("x ") + o.name + "= --quiet", message);
      ExpectUsageError(t, std::string("x ") + o.name + " '' --quiet", message);
    }
  }
  // The reports' cases: no file named after the next argument, no
  // misleading message about the stores.
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) /
                                    ("tool_cli_empty_" + std::to_string(getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  for (const auto& [args, message] : std::vector<std::pair<std::string, std::string>>{
           {"s --save-cam= --quiet", "--save-cam: an empty value; expected cam.json"},
           {"s --stats= -o b.exr", "--stats: an empty value; expected stats.json"}}) {
    const testing::CommandResult r = testing::RunCommand(
        "cd " + dir.string() + " && " + VOX_RENDER_BIN + " " + args + " </dev/null");
    EXPECT_EQ(r.code, 2) << args << "\n" << r.output;
    EXPECT_EQ(r.output, "vox-render: " + message + "\nsee vox-render --help\n") << args;
  }
  EXPECT_TRUE(std::filesystem::is_empty(dir));
  std::filesystem::remove_all(dir);
}

// Absurd values are refused with the valid range (exit 2, before any work).
TEST(ToolCommandLine, AbsurdValuesAreRefusedWithTheirRange) {
  const Tool& ingest = Tools()[0];
  const Tool& render = Tools()[1];
  const Tool& probe = Tools()[2];
  ExpectUsageError(ingest, "in.vdb out --isovalue 1e308",
                   "--isovalue 1e308: outside a grid value's range, -3.4e38..3.4e38 (a float's)");
  ExpectUsageError(ingest, "in.vdb out --threshold -1e39",
                   "--threshold -1e39: outside a grid value's range, -3.4e38..3.4e38 (a float's)");
  ExpectUsageError(render, "s --tiles 1/1000000000",
                   "--tiles '1/1000000000': N must be in 1..4194304, the most tiles an image has");
  for (const Tool* t : {&render, &probe})
    ExpectUsageError(*t, "s --cache-mb 99999999",
                     "--cache-mb '99999999': expected a whole number of MiB in 1..4194304 (4 TiB)");
  // More memory than the machine has, RAM and swap together: the range is this machine's.
  for (const Tool* t : {&ingest, &render, &probe}) {
    const ToolRun r = RunTool(*t, "s --memory-mb 99999999999");
    EXPECT_EQ(r.code, 2) << t->name << "\n" << r.err;
    const std::string head = t->name + ": --memory-mb '99999999999': 99999999999 MiB is more "
                             "memory than this machine has (";
    EXPECT_EQ(r.err.rfind(head, 0), 0u) << r.err;
    EXPECT_NE(r.err.find(" MiB of RAM and swap); expected 1.."), std::string::npos) << r.err;
  }
}

// The values docs/usage.md calls bad flags exit 2, saying what is expected.
TEST(ToolCommandLine, BadTileSizeAndSplitAreUsageErrors) {
  const Tool& render = Tools()[1];
  const Tool& probe = Tools()[2];
  for (const char* size : {"0", "4", "5000"})
    ExpectUsageError(render, std::string("s --tile-size ") + size,
                     std::string("--tile-size '") + size + "': expected a tile side in pixels, 8..4096");
  for (const Tool* t : {&render, &probe})
    for (const char* split : {"abc", "3+", "+3", "3+x", "1234"})
      ExpectUsageError(*t, std::string("s --split ") + split,
                       std::string("--split '") + split +
                           "': expected N1+N2 or N1, whole numbers of levels (e.g. 6+5)");
}

// --flag=value is --flag value: the same value checks, the same message.
TEST(ToolCommandLine, FlagEqualsValueIsFlagSpaceValue) {
  for (const Tool& t : Tools()) {
    for (const std::string value : {"abc", "-5", "0"}) {
      const ToolRun spaced = RunTool(t, "/nonexistent-vox " + t.value_flag + " " + value);
      const ToolRun joined = RunTool(t, "/nonexistent-vox " + t.value_flag + "=" + value);
      EXPECT_EQ(spaced.code, joined.code) << t.name << " " << value;
      EXPECT_EQ(spaced.err, joined.err) << t.name << " " << value;
    }
  }
  // Every option of the tools whose options Python shares, with a value each
  // accepts or refuses: the same outcome in both spellings.
  const std::pair<std::string, OptionTable> tables[] = {
      {VOX_INGEST_BIN, IngestOptionTable()},
      {VOX_RENDER_BIN, RenderOptionTable()},
      {VOX_PROBE_BIN, ProbeOptionTable()},
  };
  for (const auto& [binary, table] : tables) {
    for (const OptionSpec& o : table) {
      if (o.arity != FlagArity::kValue || std::string(o.name) == "-o") continue;
      const std::string head = binary + " /nonexistent-vox /nonexistent-vox-2 ";
      const testing::CommandResult spaced = testing::RunCommand(head + o.name + " 7 </dev/null");
      const testing::CommandResult joined = testing::RunCommand(head + o.name + "=7 </dev/null");
      EXPECT_EQ(spaced.code, joined.code) << binary << " " << o.name;
      EXPECT_EQ(spaced.output, joined.output) << binary << " " << o.name;
      EXPECT_EQ(joined.output.find("unknown option"), std::string::npos) << joined.output;
    }
  }
}

// --flag=value does its work: a store generated, pyramided, inspected,
// rendered in two parts, merged and probed with values given after '='.
TEST(ToolCommandLine, ToolsRunWithFlagEqualsValue) {
  const std::filesystem::path dir =
      std::filesystem::path(::testing::TempDir()) / ("tool_cli_" + std::to_string(getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  const std::string store = (dir / "s").string();
  const auto run = [](const std::string& cmd) {
    const testing::CommandResult r = testing::RunCommand(cmd + " </dev/null");
    EXPECT_EQ(r.code, 0) << cmd << "\n" << r.output;
    return r.output;
  };
  run(std::string(VOX_GEN_BIN) + " sphere " + store + " --size=32 --levels=auto --no-lod --quiet");
  run(std::string(VOX_INGEST_BIN) + " --add-lod=" + store + " --zstd-level=5 --quiet");
  EXPECT_TRUE(std::filesystem::exists(store + "/lod"));
  EXPECT_NE(run(std::string(VOX_INFO_BIN) + " " + store + " --verify --cache-mb=8").find("vox store"),
            std::string::npos);
  std::string parts;
  for (int part = 1; part <= 2; ++part) {
    const std::string exr = (dir / ("p" + std::to_string(part) + ".exr")).string();
    run(std::string(VOX_RENDER_BIN) + " " + store + " --size=24x16 --tile-size=8 --tiles=" +
        std::to_string(part) + "/2 --threads=1 --quiet -o" + exr);
    parts += " " + exr;
  }
  run(std::string(VOX_MERGE_BIN) + parts + " -o " + (dir / "m.exr").string() +
      " --preview=" + (dir / "m.png").string() + " --quiet");
  EXPECT_TRUE(std::filesystem::exists(dir / "m.exr"));
  EXPECT_TRUE(std::filesystem::exists(dir / "m.png"));
  const testing::CommandResult probe = testing::RunCommand(
      "echo '-100 0.5 0.5 1 0 0' | " + std::string(VOX_PROBE_BIN) + " " + store +
      " --cache-mb=8 --tracer=render");
  EXPECT_EQ(probe.code, 0) << probe.output;
  EXPECT_EQ(probe.output.rfind("hit ", 0), 0u) << probe.output;
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace vox
