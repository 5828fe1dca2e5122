// vox::OptionSpec and vox::ParseCommandLine: the command line of every vox
// tool. A tool describes its options once, as a table of OptionSpec (name,
// switch or value, help group, help text); ParseCommandLine builds the parser
// (CLI11, kept inside cli.cpp) from that table and hands each option given to
// the tool's apply function, so values are checked where they are applied.
// The Python module reads the same tables for its keyword arguments
// (tools/common/options.h), so keywords and flags cannot drift apart.
//
// What every tool's command line does:
//   --flag value, --flag=value, -o value; repeated flags are applied in order
//   (the last value wins unless the apply function says otherwise);
//   a switch takes no value (--quiet=1 is refused); a value is never empty
//   (--stats= and --stats "" are refused, naming the flag);
//   -h, --help: the help, grouped by topic, on stdout; exit 0;
//   --version: ToolMain's (tool_main.h), wherever it stands;
//   a bad command line: one line "vox-x: MESSAGE" and "see vox-x --help" on
//   stderr; exit 2.
//
// Thread safety: the tables are constants; ParseCommandLine is called from main.
#ifndef VOX_TOOLS_COMMON_CLI_H_
#define VOX_TOOLS_COMMON_CLI_H_

#include <functional>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/util/status.h"

namespace vox {

enum class FlagArity { kUnknown, kSwitch, kValue };

// One option of a tool.
struct OptionSpec {
  const char* name;        // as typed: "--zstd-level", "-o"
  FlagArity arity;         // kSwitch or kValue
  const char* value_name;  // the value's name in the help ("L", "cam.json"); "" for a switch
  const char* group;       // the help's heading ("Output"); "" hides the option from the help
  const char* help;        // one paragraph (the help wraps it)
};

using OptionTable = std::span<const OptionSpec>;

// The entry named `flag` ("--zstd-level"), or nullptr.
const OptionSpec* FindOption(OptionTable table, std::string_view flag);

// kSwitch or kValue for an entry of `table`, kUnknown for any other flag.
FlagArity ArityOf(OptionTable table, std::string_view flag);

// A tool's command line: its options and the texts around them in the help.
struct CommandLineSpec {
  const char* program;      // "vox-render"
  const char* usage;        // synopsis lines after "usage: " ("vox-render STORE_DIR [options]")
  const char* description;  // one paragraph under the synopsis
  OptionTable options;
  const char* footer = "";  // preformatted lines after the options (may be "")
};

// Applies one option: `flag` as in the table, `value` "" for a switch. A
// non-OK status refuses the command line with its message.
using ApplyOption = std::function<Status(const std::string& flag, const std::string& value)>;

// Parses argv[1..argc): calls `apply` for each option in command-line order
// and appends the other arguments to *positional ("--" ends the options).
// Returns nullopt when the tool should run, else the exit code after
// printing: 0 for --help (on stdout), 2 for a bad command line or a value
// `apply` refused (UsageError).
std::optional<int> ParseCommandLine(const CommandLineSpec& spec, int argc,
                                    const char* const* argv, const ApplyOption& apply,
                                    std::vector<std::string>* positional);

// The help text --help prints.
std::string FormatHelp(const CommandLineSpec& spec);

// Prints "PROGRAM: MESSAGE" and "see PROGRAM --help" on stderr; returns 2,
// the exit code of a bad command line.
int UsageError(const std::string& program, const std::string& message);

// `program` and argv[1..argc), joined by spaces (as a store records how it
// was made).
std::string CommandLineText(const std::string& program, int argc, const char* const* argv);

}  // namespace vox

#endif  // VOX_TOOLS_COMMON_CLI_H_
