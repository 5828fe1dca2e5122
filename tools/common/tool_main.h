// vox::ToolMain: the main of every vox command-line program around the
// tool's own `run`. `--version` anywhere among the arguments prints
// "NAME VERSION (git DESCRIBE)" (version.h) on standard output and exits 0
// without running the tool. Otherwise the exit codes are what `run` returns
// (0 done, 1 failed, 2 bad command line, as each tool documents); an
// allocation failure anywhere (an image, a brick, a table sized from input)
// ends with a clear message and exit 1, never an abort. SIGPIPE is
// ignored: a write to a pipe whose reader is gone fails (EPIPE) and the tool
// handles it as any failed write (temporaries removed, exit 1).
//
// Thread safety: called once, from main.
#ifndef VOX_TOOLS_COMMON_TOOL_MAIN_H_
#define VOX_TOOLS_COMMON_TOOL_MAIN_H_

namespace vox {

// `name` prefixes the message ("vox-render: out of memory ...") and starts
// the --version line.
int ToolMain(const char* name, int argc, char** argv, int (*run)(int argc, char** argv));

}  // namespace vox

#endif  // VOX_TOOLS_COMMON_TOOL_MAIN_H_
