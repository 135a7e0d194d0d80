#!/usr/bin/python3
"""Checks that every --help answers at once, and with the binary's own text.

usage: /usr/bin/python3 tools/check_help.py [BINARY=PATH ...]
       (ctest help_texts_match_the_binaries passes every tool of its build tree
       that has a usage text, with the path CMake built it at)

A binary's usage text is tools/help/<binary>.txt: the binary embeds it
(cmake/HermesHelp.cmake) and ./hermes prints the file for --help. Checked:

  * every binary ./hermes runs (run_tool / run_ros_tool in main(), every
    tools/bench_NAME.cc behind ./hermes bench NAME) has its text in tools/help/,
    and every text there belongs to a tool source;
  * ./hermes CMD --help and -h print exactly that text, exit 0, write nothing on
    stderr and build, configure or install nothing: they run with build folders
    that do not exist (and must stay so) and with cmake, make, apt-get and sudo
    replaced by stubs that report being called;
  * each BINARY=PATH given: `PATH --help` (stdout and stderr) prints the same text;
    a binary not built yet is reported and the test is skipped (exit 77) unless
    something is wrong;
  * the script's own commands (setup, build, test, demo, keys, bench and its
    script benchmarks) answer --help and -h the same way, and ./hermes bench
    lists every benchmark without building.

Each problem is printed on a line; the last line is
"help texts: N checked, M not built, K bad". Exit 0 when nothing is bad, 1 when
something is, 77 when nothing is bad but a binary was not built. Python 3
standard library only.
"""

import glob
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
HERMES = os.path.join(ROOT, "hermes")
HELP_DIR = os.path.join(ROOT, "tools", "help")
SKIP = 77
TIMEOUT_S = 20      # a --help that would build is stopped here
INSTANT_S = 5.0     # what "at once" allows on a loaded 2-core machine
TREE_EXCLUDE = ("build", "results", "data_cache", ".git")
STUBS = ("cmake", "make", "gmake", "ninja", "apt-get", "sudo", "catkin_make")


def read(path):
    with open(path, encoding="utf-8") as f:
        return f.read()


def tool_sources():
    """binary name -> source of every tools/<stem>.cc of the tree (hermes_<stem>)."""
    found = {}
    for p in glob.glob(os.path.join(ROOT, "**", "tools", "*.cc"), recursive=True):
        rel = os.path.relpath(p, ROOT)
        if rel.split(os.sep)[0].startswith(TREE_EXCLUDE):
            continue
        found["hermes_" + os.path.splitext(os.path.basename(p))[0]] = rel
    return found


def script_commands(script):
    """binary -> ./hermes words that run it (run_tool / run_ros_tool branches of main())."""
    m = re.search(r"^main\(\) \{(.*?)^\}", script, re.S | re.M)
    if not m:
        raise SystemExit("check_help: no main() in %s" % HERMES)
    out = {}
    for bm in re.finditer(r"^\s*([A-Za-z0-9_-]+)\)\s*(?:run_tool|run_ros_tool)\s+(hermes_[A-Za-z0-9_]+)",
                          m.group(1), re.M):
        out[bm.group(2)] = [bm.group(1)]
    return out


class Sandbox:
    """Build folders that do not exist and stubs for every tool that builds or installs."""

    def __init__(self):
        self.dir = tempfile.mkdtemp(prefix="hermes_check_help.")
        self.stub_dir = os.path.join(self.dir, "stubs")
        self.called = os.path.join(self.dir, "called")
        os.makedirs(self.stub_dir)
        for name in STUBS:
            path = os.path.join(self.stub_dir, name)
            with open(path, "w") as f:
                f.write("#!/bin/sh\necho \"%s $*\" >> '%s'\nexit 1\n" % (name, self.called))
            os.chmod(path, 0o755)
        self.build = os.path.join(self.dir, "build")
        self.build_noros = os.path.join(self.dir, "build-noros")
        self.env = dict(os.environ, HERMES_BUILD_DIR=self.build, HERMES_BUILD_NOROS_DIR=self.build_noros,
                        PATH=self.stub_dir + os.pathsep + os.environ.get("PATH", ""))

    def run(self, argv):
        """(exit code, stdout, stderr, seconds, problems) of ./hermes ARGV."""
        if os.path.exists(self.called):
            os.remove(self.called)
        t0 = time.monotonic()
        p = subprocess.Popen([HERMES] + argv, cwd=ROOT, env=self.env, stdin=subprocess.DEVNULL,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
        problems = []
        try:
            out, err = p.communicate(timeout=TIMEOUT_S)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            out, err = p.communicate()
            problems.append("did not answer within %d s" % TIMEOUT_S)
        seconds = time.monotonic() - t0
        if os.path.exists(self.called):
            problems.append("ran " + "; ".join(read(self.called).split("\n")).strip("; "))
        for d in (self.build, self.build_noros):
            if os.path.exists(d):
                problems.append("created the build folder %s" % os.path.basename(d))
                shutil.rmtree(d, ignore_errors=True)
        if seconds > INSTANT_S:
            problems.append("took %.1f s" % seconds)
        return p.returncode, out.decode("utf-8", "replace"), err.decode("utf-8", "replace"), seconds, problems

    def close(self):
        shutil.rmtree(self.dir, ignore_errors=True)


def first_difference(a, b):
    al, bl = a.split("\n"), b.split("\n")
    for i, (x, y) in enumerate(zip(al, bl), 1):
        if x != y:
            return "line %d: %r against %r" % (i, x, y)
    return "line %d: one ends, the other goes on (%d against %d lines)" % (
        min(len(al), len(bl)) + 1, len(al), len(bl))


def main(argv):
    if any(a in ("-h", "--help") for a in argv):
        print(__doc__.strip())
        return 0
    built = {}
    for a in argv:
        name, sep, path = a.partition("=")
        if not sep or not name:
            print("check_help: arguments are BINARY=PATH, got '%s'" % a, file=sys.stderr)
            return 2
        built[name] = path
    script = read(HERMES)
    sources = tool_sources()
    commands = script_commands(script)
    for binary in sources:
        if binary.startswith("hermes_bench_"):
            commands[binary] = ["bench", binary[len("hermes_bench_"):]]
    texts = {os.path.splitext(os.path.basename(p))[0]: p for p in glob.glob(os.path.join(HELP_DIR, "*.txt"))}
    bad, checked, not_built = [], 0, []

    for binary in sorted(commands):
        if binary not in texts:
            bad.append("%s: ./hermes %s runs it but tools/help/%s.txt is missing" % (
                binary, " ".join(commands[binary]), binary))
    for binary in sorted(texts):
        if binary not in sources:
            bad.append("tools/help/%s.txt: no tool source */tools/%s.cc" % (binary, binary[len("hermes_"):]))

    box = Sandbox()
    try:
        for binary in sorted(texts):
            text = read(texts[binary])
            words = commands.get(binary)
            for flag in ("--help", "-h") if words else ():
                shown = "./hermes %s %s" % (" ".join(words), flag)
                rc, out, err, secs, problems = box.run(words + [flag])
                checked += 1
                if rc != 0:
                    problems.append("exit %d" % rc)
                if err.strip():
                    problems.append("stderr: %s" % err.strip().split("\n")[0])
                if out != text:
                    problems.append("differs from tools/help/%s.txt at %s" % (binary, first_difference(out, text)))
                if problems:
                    bad.append("%s: %s" % (shown, "; ".join(problems)))
            if binary in built:
                path = built[binary]
                if not os.access(path, os.X_OK):
                    not_built.append(binary)
                    continue
                r = subprocess.run([path, "--help"], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, timeout=TIMEOUT_S)
                out = (r.stdout + r.stderr).decode("utf-8", "replace")
                checked += 1
                if out != text:
                    bad.append("%s --help: differs from tools/help/%s.txt (what ./hermes prints) at %s" % (
                        binary, binary, first_difference(out, text)))
                src = sources.get(binary)
                if src and ('"hermes_help/%s.h"' % binary) not in read(os.path.join(ROOT, src)):
                    print("note: %s prints its own copy of tools/help/%s.txt (it does not include "
                          "hermes_help/%s.h); kept equal by this test" % (src, binary, binary))

        # The script's own commands, and the benchmark list.
        own = [["--help"], ["-h"], ["setup", "--help"], ["setup", "--core", "-h"], ["build", "--help"],
               ["build", "--no-ros", "-h"], ["test", "--help"], ["test", "-h"], ["demo", "--help"],
               ["demo", "-h"], ["keys", "--help"], ["keys", "add", "-h"], ["bench", "--help"], ["bench", "-h"]]
        own += [["bench", name, flag] for name in re.findall(r'"\$name" == ([A-Za-z0-9_]+) \]\] && exec', script)
                for flag in ("--help", "-h")]
        benches = sorted(b[len("hermes_bench_"):] for b in commands if b.startswith("hermes_bench_"))
        for words in own + [["bench"]]:
            shown = "./hermes " + " ".join(words)
            rc, out, err, secs, problems = box.run(words)
            checked += 1
            want_rc = 2 if words == ["bench"] else 0
            if rc != want_rc:
                problems.append("exit %d (expected %d)" % (rc, want_rc))
            if err.strip():
                problems.append("stderr: %s" % err.strip().split("\n")[0])
            if not out.strip():
                problems.append("printed nothing")
            if words[0] == "bench" and len(words) <= 2:
                listed = set(re.findall(r"^    ([A-Za-z0-9_]+)", out, re.M))
                missing = [b for b in benches if b not in listed]
                if missing:
                    problems.append("does not list %s" % ", ".join(missing))
            if problems:
                bad.append("%s: %s" % (shown, "; ".join(problems)))
    finally:
        box.close()

    for line in bad:
        print(line)
    for binary in not_built:
        print("not built: %s (cmake --build BUILD --target %s)" % (built[binary], binary))
    print("help texts: %d checked, %d not built, %d bad" % (checked, len(not_built), len(bad)))
    if bad:
        return 1
    return SKIP if not_built else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
