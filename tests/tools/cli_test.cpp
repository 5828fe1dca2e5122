// tools/common/cli.h in process: the parser built from an option table, and
// the option tables of vox-ingest, vox-render and vox-probe against the
// functions that apply them (tools/common/options.h).
#include "tools/common/cli.h"

#include <gtest/gtest.h>

#include <set>
#include <string>
#include <utility>
#include <vector>

#include "tools/common/options.h"

namespace vox {
namespace {

constexpr OptionSpec kToyOptions[] = {
    {"--count", FlagArity::kValue, "N", "Numbers", "how many"},
    {"--name", FlagArity::kValue, "NAME", "Words", "a name"},
    {"-o", FlagArity::kValue, "out.txt", "Words", "the output"},
    {"--quiet", FlagArity::kSwitch, "", "Words", "no output"},
    {"--secret", FlagArity::kSwitch, "", "", "hidden from the help"},
};
const CommandLineSpec kToy{"vox-toy", "vox-toy FILE [options]", "A toy.", kToyOptions,
                           "The footer.\n"};

struct Parsed {
  std::optional<int> exit_code;
  std::vector<std::pair<std::string, std::string>> applied;
  std::vector<std::string> positional;
  std::string out, err;
};

Parsed Parse(std::vector<const char*> args) {
  args.insert(args.begin(), "vox-toy");
  Parsed p;
  const ApplyOption apply = [&](const std::string& flag, const std::string& value) {
    if (flag == "--count" && value == "bad") return InvalidArgumentError("--count bad: no");
    p.applied.emplace_back(flag, value);
    return OkStatus();
  };
  ::testing::internal::CaptureStdout();
  ::testing::internal::CaptureStderr();
  p.exit_code = ParseCommandLine(kToy, int(args.size()), args.data(), apply, &p.positional);
  p.err = ::testing::internal::GetCapturedStderr();
  p.out = ::testing::internal::GetCapturedStdout();
  return p;
}

using Applied = std::vector<std::pair<std::string, std::string>>;

TEST(ParseCommandLine, AppliesOptionsInOrderInBothSpellings) {
  const Parsed p = Parse({"--count=3", "a", "--name", "x", "-o", "o.txt", "--quiet", "b",
                          "--count", "-2", "-op.txt"});
  EXPECT_FALSE(p.exit_code.has_value()) << p.err;
  EXPECT_EQ(p.applied, (Applied{{"--count", "3"}, {"--name", "x"}, {"-o", "o.txt"},
                                {"--quiet", ""}, {"--count", "-2"}, {"-o", "p.txt"}}));
  EXPECT_EQ(p.positional, (std::vector<std::string>{"a", "b"}));
  EXPECT_EQ(p.err, "");
}

TEST(ParseCommandLine, DoubleDashEndsTheOptions) {
  const Parsed p = Parse({"--quiet", "--", "--count", "-"});
  EXPECT_FALSE(p.exit_code.has_value()) << p.err;
  EXPECT_EQ(p.applied, (Applied{{"--quiet", ""}}));
  EXPECT_EQ(p.positional, (std::vector<std::string>{"--count", "-"}));
}

TEST(ParseCommandLine, ErrorsAreOneLineAndAPointerToTheHelp) {
  const std::pair<std::vector<const char*>, std::string> cases[] = {
      {{"a", "--bogus"}, "unknown option --bogus"},
      {{"--bogus=3", "a"}, "unknown option --bogus"},
      {{"a", "-x"}, "unknown option -x"},
      {{"a", "--count"}, "--count needs a value"},
      {{"a", "-o"}, "-o needs a value"},
      {{"a", "--quiet=1"}, "--quiet is a switch and takes no value"},
      {{"a", "--count=bad"}, "--count bad: no"},
      {{"a", "--count", "bad", "--bogus"}, "--count bad: no"},
  };
  for (const auto& [args, message] : cases) {
    const Parsed p = Parse(args);
    EXPECT_EQ(p.exit_code, 2) << message;
    EXPECT_EQ(p.err, "vox-toy: " + message + "\nsee vox-toy --help\n");
    EXPECT_EQ(p.out, "");
  }
}

TEST(ParseCommandLine, HelpIsGroupedByTopic) {
  for (const char* flag : {"--help", "-h"}) {
    const Parsed p = Parse({"a", flag});
    EXPECT_EQ(p.exit_code, 0);
    EXPECT_EQ(p.err, "");
    EXPECT_EQ(p.out, FormatHelp(kToy));
  }
  const std::string help = FormatHelp(kToy);
  EXPECT_EQ(help.rfind("usage: vox-toy FILE [options]\n\nA toy.\n\nNumbers:\n  --count N", 0), 0u)
      << help;
  const size_t words = help.find("\nWords:\n"), general = help.find("\nGeneral:\n");
  EXPECT_LT(help.find("--count N"), words) << help;
  EXPECT_LT(words, help.find("--name NAME")) << help;
  EXPECT_LT(help.find("-o out.txt"), general) << help;
  EXPECT_NE(help.find("--version"), std::string::npos) << help;
  EXPECT_EQ(help.find("--secret"), std::string::npos) << help;
  EXPECT_EQ(help.substr(help.size() - 13), "\nThe footer.\n") << help;
}

TEST(ParseCommandLine, VersionPrintsTheVersionLine) {
  const Parsed p = Parse({"--version"});
  EXPECT_EQ(p.exit_code, 0);
  EXPECT_EQ(p.out.rfind("vox-toy ", 0), 0u) << p.out;
  EXPECT_NE(p.out.find(" (git "), std::string::npos) << p.out;
}

// Each tool's table against its Apply function: every entry is a flag the
// function knows, with a value name exactly when it takes a value.
struct Table {
  const char* tool;
  OptionTable options;
  std::function<Status(const std::string&, const std::string&)> apply;
};

std::vector<Table> Tables() {
  static IngestCommand ingest;
  static RenderJobOptions render;
  static ProbeOptions probe;
  return {
      {"vox-ingest", IngestOptionTable(),
       [](const std::string& f, const std::string& v) { return ApplyIngestFlag(&ingest, f, v); }},
      {"vox-render", RenderOptionTable(),
       [](const std::string& f, const std::string& v) { return ApplyRenderFlag(&render, f, v); }},
      {"vox-probe", ProbeOptionTable(),
       [](const std::string& f, const std::string& v) { return ApplyProbeFlag(&probe, f, v); }},
  };
}

TEST(OptionTables, EveryEntryIsAFlagItsToolApplies) {
  for (const Table& t : Tables()) {
    std::set<std::string> names;
    for (const OptionSpec& o : t.options) {
      const std::string name = o.name;
      EXPECT_TRUE(names.insert(name).second) << t.tool << ": " << name << " twice";
      EXPECT_TRUE(name.rfind("--", 0) == 0 || (name.size() == 2 && name[0] == '-')) << name;
      EXPECT_EQ(o.arity == FlagArity::kValue, *o.value_name != '\0') << t.tool << " " << name;
      EXPECT_NE(*o.help, '\0') << t.tool << " " << name;
      EXPECT_EQ(FindOption(t.options, name), &o);
      EXPECT_EQ(ArityOf(t.options, name), o.arity);
      const Status s = t.apply(name, o.arity == FlagArity::kValue ? "1" : "");
      EXPECT_EQ(s.message().find("unknown option"), std::string::npos) << t.tool << " " << name;
    }
    EXPECT_EQ(ArityOf(t.options, "--no-such-flag"), FlagArity::kUnknown);
    EXPECT_EQ(t.apply("--no-such-flag", "").message(), "unknown option --no-such-flag");
  }
}

}  // namespace
}  // namespace vox
