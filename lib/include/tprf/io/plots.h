#pragma once
/// Figures are drawn by python/tprf_plots.py with matplotlib, in a child process: the library writes
/// a figure's data (JSON or CSV) and hands it to the script; it renders no fonts itself.
///
/// The script is $TPRF_PLOT_SCRIPT when that is set; else the copy that `cmake --install` put beside
/// the running program (PREFIX/bin/tprf, PREFIX/share/tprf/tprf_plots.py), so that an installed tprf
/// uses its own; else the copy in the source tree this library was built from (a build tree); else
/// PREFIX/share/tprf/tprf_plots.py for the prefix configured at build time. The Python is $TPRF_PYTHON
/// when that is set (a path, or a name looked up on the PATH); else the first `python3` along the
/// PATH that can import matplotlib and numpy (a pyenv shim first on the PATH without them is passed
/// over for the system's /usr/bin/python3, say).

#include <filesystem>
#include <string>
#include <vector>

namespace tprf {

/// The path of python/tprf_plots.py, as described above (the configured install path when no copy exists).
std::filesystem::path plot_script();

/// Runs `PYTHON plot_script() ARGS...` (no shell) and waits for it, trying the Pythons described
/// above in turn. Returns true when the script drew its figure; false when no Python could import
/// matplotlib and numpy (the script exits with status 3 then), none could be started, or the script
/// failed otherwise (a crash, bad data, an unwritable output): then `failure`, when given, says how,
/// with the last line the script wrote to stderr. A figure is a view of data already written, so its
/// failure is never an exception.
bool run_plot_script(const std::vector<std::string>& args, std::string* failure = nullptr);

/// One line for the user when run_plot_script returned false: that `png` was not drawn and why (the
/// script's `failure`, or no matplotlib and how to install it), and the command that draws it later
/// (`python3 SCRIPT ARGS...`, quoted for a POSIX shell).
std::string plot_not_drawn_message(const std::filesystem::path& png, const std::vector<std::string>& args,
                                   const std::string& failure = "");

}  // namespace tprf
