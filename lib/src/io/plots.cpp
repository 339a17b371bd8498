#include "tprf/io/plots.h"

#include "tprf/core/cancel.h"
#include "tprf/core/error.h"
#include "tprf/io/atomic_file.h"

#include <fcntl.h>
#include <poll.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cctype>
#include <cerrno>
#include <csignal>
#include <cstdlib>
#include <cstdio>
#include <cstring>
#include <string_view>
#include <system_error>

extern char** environ;

namespace tprf {

namespace fs = std::filesystem;

namespace {

/// tprf_plots.py's exit status when it cannot import matplotlib or numpy.
constexpr int kNoMatplotlib = 3;
/// A shell's (or a pyenv shim's) status for a command it cannot find.
constexpr int kNotFound = 127;
/// The most of a child's stderr kept for an error message.
constexpr std::size_t kMaxStderr = 1 << 16;

std::string environment(const char* name) {
    const char* v = std::getenv(name);
    return v ? v : "";
}

bool is_file(const fs::path& p) {
    std::error_code ec;
    return fs::is_regular_file(p, ec);
}

/// $TPRF_PYTHON alone when set; else every distinct `python3` along the PATH, in order.
std::vector<std::string> pythons() {
    if (std::string p = environment("TPRF_PYTHON"); !p.empty()) return {p};
    std::vector<std::string> out;
    std::vector<fs::path> seen;
    std::string path = environment("PATH");
    if (path.empty()) {  // as execvp: the system's default search path
        char buf[256] = "";
        if (::confstr(_CS_PATH, buf, sizeof buf) > 0) path = buf;
    }
    std::size_t begin = 0;
    while (begin <= path.size()) {
        const std::size_t end = std::min(path.find(':', begin), path.size());
        if (end == begin) {  // an empty element (the current directory) is not searched for a plot tool
            begin = end + 1;
            continue;
        }
        const fs::path dir = path.substr(begin, end - begin);
        const fs::path candidate = dir / "python3";
        std::error_code ec;
        const fs::path real = fs::canonical(candidate, ec);
        if (!ec && is_file(real) && ::access(real.c_str(), X_OK) == 0 &&
            std::find(seen.begin(), seen.end(), real) == seen.end()) {
            seen.push_back(real);
            out.push_back(candidate.string());
        }
        begin = end + 1;
    }
    return out;
}

struct ChildResult {
    bool started = false;
    int exit_status = -1;  ///< -1 when killed by a signal
    int signal = 0;
    std::string err;       ///< what it wrote to stderr (the last kMaxStderr bytes)
};

/// Runs argv (argv[0] looked up on the PATH when it has no '/') with stdin and stdout on /dev/null and
/// stderr captured, and waits for it.
ChildResult run_child(const std::vector<std::string>& argv) {
    int fds[2];
    if (::pipe2(fds, O_CLOEXEC) != 0) throw Error(std::string("cannot create a pipe: ") + std::strerror(errno));
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_addopen(&actions, 0, "/dev/null", O_RDONLY, 0);
    posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
    posix_spawn_file_actions_adddup2(&actions, fds[1], 2);
    std::vector<char*> args;
    for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    pid_t pid = 0;
    const int e = posix_spawnp(&pid, args[0], &actions, nullptr, args.data(), environ);
    posix_spawn_file_actions_destroy(&actions);
    ::close(fds[1]);
    ChildResult r;
    if (e != 0) {
        ::close(fds[0]);
        return r;
    }
    r.started = true;
    char buf[4096];
    bool stopped = false;
    for (;;) {
        // Woken every 100 ms to see whether the run was cancelled: then the child is stopped too, and the
        // caller's next check throws (a plot takes a second or two; a cancelled run must not wait).
        pollfd readable{fds[0], POLLIN, 0};
        if (::poll(&readable, 1, 100) == 0 || (readable.revents & (POLLIN | POLLHUP | POLLERR)) == 0) {
            if (cancel_requested() && !stopped) stopped = ::kill(pid, SIGTERM) == 0;
            continue;
        }
        const ssize_t n = ::read(fds[0], buf, sizeof buf);
        if (n == 0) break;
        if (n < 0) {
            if (errno == EINTR) continue;
            break;
        }
        r.err.append(buf, std::size_t(n));
        if (r.err.size() > kMaxStderr) r.err.erase(0, r.err.size() - kMaxStderr);
    }
    ::close(fds[0]);
    int status = 0;
    while (::waitpid(pid, &status, 0) < 0) {
        if (errno == EINTR) continue;
        // ECHILD: the host process reaps children itself (SIGCHLD ignored); the status is unknown.
        r.err += std::string("cannot wait for ") + argv[0] + ": " + std::strerror(errno);
        return r;
    }
    if (WIFEXITED(status))
        r.exit_status = WEXITSTATUS(status);
    else if (WIFSIGNALED(status))
        r.signal = WTERMSIG(status);
    return r;
}

std::string last_line(std::string_view text) {
    while (!text.empty() && (text.back() == '\n' || text.back() == '\r' || text.back() == ' ')) text.remove_suffix(1);
    const std::size_t nl = text.rfind('\n');
    return std::string(nl == std::string_view::npos ? text : text.substr(nl + 1));
}

/// `s` as one word of a POSIX shell: as is when it holds only safe characters, else in single quotes.
std::string shell_word(const std::string& s) {
    const bool safe = !s.empty() && std::all_of(s.begin(), s.end(), [](char c) {
        return std::isalnum(static_cast<unsigned char>(c)) || std::strchr("_-./:=+,@%", c) != nullptr;
    });
    if (safe) return s;
    std::string out = "'";
    for (const char c : s) out += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return out + "'";
}

}  // namespace

fs::path plot_script() {
    if (std::string s = environment("TPRF_PLOT_SCRIPT"); !s.empty()) return s;
    // PREFIX/bin/tprf finds PREFIX/share/tprf/tprf_plots.py, also when the prefix given to
    // `cmake --install` was not the configured one.
    std::error_code ec;
    const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    if (!ec) {
        const fs::path beside = exe.parent_path().parent_path() / TPRF_PLOT_SCRIPT_DATADIR / "tprf" / "tprf_plots.py";
        if (is_file(beside)) return beside;
    }
    const fs::path source = TPRF_PLOT_SCRIPT_SOURCE;
    if (is_file(source)) return source;
    return TPRF_PLOT_SCRIPT_INSTALLED;
}

bool run_plot_script(const std::vector<std::string>& args, std::string* failure) {
    const fs::path script = plot_script();
    for (const std::string& python : pythons()) {
        std::vector<std::string> argv = {python, script.string()};
        argv.insert(argv.end(), args.begin(), args.end());
        const ChildResult r = run_child(argv);
        if (!r.started || r.exit_status == kNoMatplotlib || r.exit_status == kNotFound) continue;
        if (r.exit_status == 0) return true;
        const std::string why = r.signal != 0 ? "killed by signal " + std::to_string(r.signal)
                                              : "exit status " + std::to_string(r.exit_status);
        const std::string line = last_line(r.err);
        // The figure is a view of data already written: its failure is reported, not fatal.
        if (failure) *failure = python + " " + script.string() + ": " + why + (line.empty() ? "" : ": " + line);
        return false;
    }
    return false;
}

std::string plot_not_drawn_message(const fs::path& png, const std::vector<std::string>& args,
                                   const std::string& failure) {
    const std::string python = environment("TPRF_PYTHON");
    std::string message = png.string();
    if (!failure.empty()) {
        message += " not drawn: " + failure + "; draw it again with: python3 " + shell_word(plot_script().string());
        for (const std::string& a : args) message += ' ' + shell_word(a);
        return message;
    }
    if (python.empty()) {
        message += " not drawn: no python3 on the PATH can import matplotlib";
    } else {
        message += " not drawn: TPRF_PYTHON (";
        message += python;
        message += ") cannot be run or cannot import matplotlib";
    }
    message += " (Debian: apt-get install python3-matplotlib); draw it later, with a python3 that has it: ";
    message += "python3 ";
    message += shell_word(plot_script().string());
    for (const std::string& a : args) {
        message += ' ';
        message += shell_word(a);
    }
    return message;
}

}  // namespace tprf
