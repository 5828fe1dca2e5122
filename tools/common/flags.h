// vox::FlagReader and the number parsers. The tools parse their command
// lines with tools/common/cli.h and their values with ParseInt/ParseDouble;
// FlagReader (flags, their values, positional arguments, walked by hand) is
// left to the benchmark programs (tools/bench). Values are parsed, not
// judged: ranges that a library checks are left to the library.
//
// Thread safety: FlagReader is thread-compatible; the parsers are pure.
#ifndef VOX_TOOLS_COMMON_FLAGS_H_
#define VOX_TOOLS_COMMON_FLAGS_H_

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

namespace vox {

class FlagReader {
 public:
  // The arguments after the program name.
  FlagReader(int argc, const char* const* argv);

  // Moves to the next argument; false when there is none.
  bool Next();

  // The current argument.
  const std::string& arg() const { return args_[size_t(pos_)]; }

  // -h or --help.
  bool IsHelp() const { return arg() == "-h" || arg() == "--help"; }

  // Looks like a flag: '-' and at least one more character ("-" alone is an
  // argument, as for standard input).
  bool IsFlag() const { return arg().size() > 1 && arg()[0] == '-'; }

  // Takes the argument after the current flag as its value; nullopt when the
  // flag is the last argument.
  std::optional<std::string> Value();

  // `program` and the arguments, joined by spaces (as a store records how it
  // was made).
  std::string CommandLine(const std::string& program) const;

 private:
  std::vector<std::string> args_;
  int pos_ = -1;
};

// The most worker threads a tool accepts for --threads: each costs a stack
// and per-thread buffers, so a typo like 1000000 is refused, not obeyed.
inline constexpr int kMaxThreads = 1024;

// A whole decimal number in [lo, hi] (strtoll syntax: optional sign, leading
// blanks allowed, nothing after the digits). False, leaving *out alone, when
// `s` is empty, has other characters, overflows or is out of range.
bool ParseInt(const std::string& s, int64_t lo, int64_t hi, int64_t* out);
bool ParseInt(const std::string& s, int lo, int hi, int* out);

// A finite decimal or hexadecimal floating-point number (strtod syntax).
bool ParseDouble(const std::string& s, double* out);

// "a,b,,c" -> {"a", "b", "", "c"}; "" -> {""}.
std::vector<std::string> SplitList(const std::string& s, char sep = ',');

}  // namespace vox

#endif  // VOX_TOOLS_COMMON_FLAGS_H_
