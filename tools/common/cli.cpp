#include "tools/common/cli.h"

#include <CLI/CLI.hpp>
#include <cstdio>
#include <memory>
#include <sstream>

#include "tools/common/version.h"

namespace vox {
namespace {

// The help's layout: option names in the first kNameColumn columns, text
// wrapped to kHelpWidth in all.
constexpr size_t kNameColumn = 24;
constexpr size_t kHelpWidth = 88;

// `text` wrapped at spaces into lines of at most `width` characters (a longer
// word stays whole); '\n' in `text` breaks a line.
std::string Wrap(const std::string& text, size_t width) {
  std::string out, line;
  std::istringstream paragraphs(text);
  std::string paragraph;
  bool first_paragraph = true;
  while (std::getline(paragraphs, paragraph)) {
    if (!first_paragraph) out += '\n';
    first_paragraph = false;
    std::istringstream words(paragraph);
    std::string word;
    line.clear();
    while (words >> word) {
      if (!line.empty() && line.size() + 1 + word.size() > width) {
        out += line + '\n';
        line.clear();
      }
      line += (line.empty() ? "" : " ") + word;
    }
    out += line;
  }
  return out;
}

// The help as vox prints it: usage first, then the description, the option
// groups in the table's order, and the footer.
class HelpFormatter : public CLI::Formatter {
 public:
  explicit HelpFormatter(const CommandLineSpec& spec) : spec_(spec) { column_width(kNameColumn); }

  std::string make_help(const CLI::App* app, std::string, CLI::AppFormatMode mode) const override {
    std::string out = "usage: ";
    for (const char* c = spec_.usage; *c; ++c)  // later lines under the first
      out += *c == '\n' ? std::string("\n       ") : std::string(1, *c);
    out += "\n\n" + Wrap(spec_.description, kHelpWidth) + "\n\n";
    out += make_groups(app, mode);
    if (*spec_.footer) out += std::string("\n") + spec_.footer;
    return out;
  }

  // A heading and its options; make_groups puts a blank line between groups.
  std::string make_group(std::string group, bool is_positional,
                         std::vector<const CLI::Option*> options) const override {
    std::string out = group + ":\n";
    for (const CLI::Option* option : options) out += make_option(option, is_positional);
    return out;
  }

 private:
  const CommandLineSpec& spec_;
};

// One line for a CLI11 parse error, naming the option when CLI11's message
// starts with its name (with or without its dashes): "--levels: 1 required
// N1+N2 missing" becomes "--levels needs a value", "quiet was given a
// disallowed flag override" "--quiet is a switch and takes no value".
std::string ParseErrorLine(const CLI::ParseError& e, OptionTable table) {
  const std::string what = e.what();
  const OptionSpec* named = nullptr;
  size_t named_length = 0;
  for (const OptionSpec& o : table) {
    const std::string_view full = o.name;
    for (std::string_view name : {full, full.substr(full.find_first_not_of('-'))}) {
      if (what.size() > name.size() && what.compare(0, name.size(), name) == 0 &&
          (what[name.size()] == ':' || what[name.size()] == ' ') && name.size() > named_length) {
        named = &o;
        named_length = name.size();
      }
    }
  }
  if (named && dynamic_cast<const CLI::ArgumentMismatch*>(&e)) {
    if (named->arity == FlagArity::kValue) return std::string(named->name) + " needs a value";
    return std::string(named->name) + " is a switch and takes no value";
  }
  return what;
}

// An option's value refused by the tool's apply function.
struct Refused {
  std::string message;
};

// The CLI11 parser of `spec`; each option calls `apply` as soon as it is
// read, so options take effect in command-line order.
std::unique_ptr<CLI::App> BuildApp(const CommandLineSpec& spec, const ApplyOption& apply,
                                   std::vector<std::string>* positional) {
  auto app = std::make_unique<CLI::App>(spec.description, spec.program);
  app->formatter(std::make_shared<HelpFormatter>(spec));
  app->allow_extras();  // unknown options are reported by ParseCommandLine, by name
  for (const OptionSpec& o : spec.options) {
    const std::string flag = o.name;
    auto call = [flag, &apply](const std::string& value) {
      if (Status s = apply(flag, value); !s.ok()) throw Refused{s.message()};
    };
    const std::string help = Wrap(o.help, kHelpWidth - kNameColumn);
    CLI::Option* option =
        o.arity == FlagArity::kSwitch
            ? app->add_flag_callback(flag, [call] { call(""); }, help)->disable_flag_override()
            : app->add_option_function<std::string>(flag, call, help)->type_name(o.value_name);
    option->trigger_on_parse()->group(o.group);
  }
  app->add_option("arguments", *positional)->group("");
  // Last, under their own heading.
  app->set_help_flag("-h,--help", "print this help and exit")->group("General");
  app->set_version_flag("--version", VersionLine(spec.program),
                        "print the version and the git description of the build and exit")
      ->group("General");
  return app;
}

}  // namespace

const OptionSpec* FindOption(OptionTable table, std::string_view flag) {
  for (const OptionSpec& o : table)
    if (flag == o.name) return &o;
  return nullptr;
}

FlagArity ArityOf(OptionTable table, std::string_view flag) {
  const OptionSpec* o = FindOption(table, flag);
  return o ? o->arity : FlagArity::kUnknown;
}

std::optional<int> ParseCommandLine(const CommandLineSpec& spec, int argc,
                                    const char* const* argv, const ApplyOption& apply,
                                    std::vector<std::string>* positional) {
  // An empty value ("--stats=", or "--stats ''") names no value: refused
  // here, before CLI11, which would take the next argument for "--stats=".
  for (int i = 1; i < argc; ++i) {
    const std::string_view arg = argv[i];
    if (arg == "--") break;
    const size_t eq = arg.find('=');
    const bool empty_inline = arg.rfind("--", 0) == 0 && eq != std::string_view::npos &&
                              eq + 1 == arg.size();
    const std::string_view flag = empty_inline ? arg.substr(0, eq) : arg;
    if (ArityOf(spec.options, flag) != FlagArity::kValue) continue;
    if (empty_inline || (i + 1 < argc && argv[i + 1][0] == '\0'))
      return UsageError(spec.program, std::string(flag) + ": an empty value; expected " +
                                          FindOption(spec.options, flag)->value_name);
    ++i;  // the value, whatever it looks like
  }
  const std::unique_ptr<CLI::App> app = BuildApp(spec, apply, positional);
  try {
    app->parse(argc, argv);
  } catch (const Refused& r) {
    return UsageError(spec.program, r.message);
  } catch (const CLI::CallForHelp&) {
    std::fputs(FormatHelp(spec).c_str(), stdout);
    return std::fflush(stdout) == 0 ? 0 : 1;
  } catch (const CLI::CallForVersion&) {
    std::printf("%s\n", VersionLine(spec.program).c_str());
    return std::fflush(stdout) == 0 ? 0 : 1;
  } catch (const CLI::ParseError& e) {
    return UsageError(spec.program, ParseErrorLine(e, spec.options));
  }
  // What CLI11 left: unknown options, and the "--" that ended the options.
  for (const std::string& arg : app->remaining())
    if (arg != "--") return UsageError(spec.program, "unknown option " + arg.substr(0, arg.find('=')));
  return std::nullopt;
}

std::string FormatHelp(const CommandLineSpec& spec) {
  std::vector<std::string> unused;
  return BuildApp(spec, [](const std::string&, const std::string&) { return OkStatus(); }, &unused)
      ->help();
}

int UsageError(const std::string& program, const std::string& message) {
  std::fprintf(stderr, "%s: %s\nsee %s --help\n", program.c_str(), message.c_str(),
               program.c_str());
  return 2;
}

std::string CommandLineText(const std::string& program, int argc, const char* const* argv) {
  std::string line = program;
  for (int i = 1; i < argc; ++i) line += std::string(" ") + argv[i];
  return line;
}

}  // namespace vox
