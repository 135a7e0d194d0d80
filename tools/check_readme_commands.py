#!/usr/bin/python3
"""Checks the ./hermes commands that README.md and docs/*.md show.

usage: /usr/bin/python3 tools/check_readme_commands.py README.md [docs/*.md ...]
       (no argument: README.md and docs/*.md of the repository)

Every line of a fenced code block marked ```bash, ```sh, ```shell or unmarked
(```) is read as shell (lines ending in a backslash are joined, comments
dropped); every command in it that starts with ./hermes (also after &&, ||, ;
or |, or after VAR=value assignments) is checked without running any work:

  * the subcommand is one of the `case` branches of main() in ./hermes;
  * every --option it uses appears in that subcommand's --help output
    (./hermes SUB --help, which never builds or installs anything: a tool's
    text comes from tools/help/, see tools/check_help.py);
  * ./hermes bench NAME: NAME has its usage text tools/help/hermes_bench_NAME.txt
    (or is a benchmark the script runs itself, e.g. realtime), its options
    those of ./hermes bench NAME --help.

Each bad command is printed as FILE:LINE: what is wrong. The last line is
"readme commands: N checked, M skipped, K bad". Exit 0 when nothing is bad,
1 otherwise, 2 on bad usage. Python 3 standard library only.
"""

import glob
import os
import re
import shlex
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
HERMES = os.path.join(ROOT, "hermes")
HELP_DIR = os.path.join(ROOT, "tools", "help")
SHELL_LANGS = {"", "bash", "sh", "shell"}
OPERATORS = {"&&", "||", ";", "|", "&", "(", ")", ";;", "|&"}
HELP_TIMEOUT_S = 120


def read(path):
    with open(path, encoding="utf-8") as f:
        return f.read()


# ---------------------------------------------------------------- the hermes script
class Cli:
    """What ./hermes offers, read from the script (never by running work)."""

    def __init__(self):
        self.script = read(HERMES)
        self.branches = self._branches()          # sub -> text of its case branch
        self.special_bench = set(re.findall(r'"\$name" == ([A-Za-z0-9_]+) \]\] && exec', self.script))
        self.help_cache = {}

    def _branches(self):
        m = re.search(r"^main\(\) \{(.*?)^\}", self.script, re.S | re.M)
        if not m:
            raise SystemExit("check_readme_commands: no main() in %s" % HERMES)
        body = m.group(1)
        case = re.search(r'case "\$cmd" in\n(.*?)\n\s*esac', body, re.S)
        if not case:
            raise SystemExit("check_readme_commands: no case list in main() of %s" % HERMES)
        branches = {}
        # a branch: "  name|alias) ... ;;" possibly over several lines
        for bm in re.finditer(r"^\s*([A-Za-z0-9_|-]+)\)(.*?);;", case.group(1), re.S | re.M):
            for name in bm.group(1).split("|"):
                branches[name] = bm.group(2)
        return branches

    def run_help(self, argv):
        key = tuple(argv)
        if key not in self.help_cache:
            try:
                r = subprocess.run([HERMES] + argv + ["--help"], cwd=ROOT, stdin=subprocess.DEVNULL,
                                   stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                   timeout=HELP_TIMEOUT_S)
                out = r.stdout.decode("utf-8", "replace")
                self.help_cache[key] = (out, None if out.strip() else
                                        "'./hermes %s --help' printed nothing (exit %d)" % (" ".join(argv), r.returncode))
            except subprocess.TimeoutExpired:
                self.help_cache[key] = ("", "'./hermes %s --help' took over %d s" % (" ".join(argv), HELP_TIMEOUT_S))
        return self.help_cache[key]

    def help_for(self, sub, rest):
        """(help text, skip reason, error, words consumed after sub) for ./hermes SUB REST."""
        if sub == "bench":
            name = rest[0] if rest and not rest[0].startswith("-") else None
            if name is None:
                out, err = self.run_help(["bench"])
                return out, None, err, 0
            if name in self.special_bench or os.path.isfile(os.path.join(HELP_DIR, "hermes_bench_%s.txt" % name)):
                out, err = self.run_help(["bench", name])
                return out, None, err, 1
            return None, None, "no benchmark '%s' (no tools/help/hermes_bench_%s.txt)" % (name, name), 1
        out, err = self.run_help([sub])
        return out, None, err, 0


# ---------------------------------------------------------------- markdown
def shell_lines(path):
    """(line number, text) of every logical line in shell code blocks of a markdown file."""
    lines = read(path).split("\n")
    fence = None  # (char, length, is_shell)
    pending, pending_no = "", 0
    for no, line in enumerate(lines, 1):
        m = re.match(r"^\s*(`{3,}|~{3,})\s*([^\s`]*)", line)
        if fence is None:
            if m:
                lang = m.group(2).lower()
                fence = (m.group(1)[0], len(m.group(1)), lang in SHELL_LANGS)
            continue
        if m and m.group(1)[0] == fence[0] and len(m.group(1)) >= fence[1] and not m.group(2):
            if pending:
                yield pending_no, pending
            fence, pending = None, ""
            continue
        if not fence[2]:
            continue
        if not pending:
            pending_no = no
        if line.rstrip().endswith("\\"):
            pending += line.rstrip()[:-1] + " "
            continue
        yield pending_no, pending + line
        pending = ""


def hermes_commands(text):
    """Token lists of every ./hermes command in one shell line."""
    lex = shlex.shlex(text, posix=True, punctuation_chars=True)
    lex.whitespace_split = True
    tokens = list(lex)
    segments, cur = [], []
    for t in tokens:
        if t in OPERATORS:
            segments.append(cur)
            cur = []
        else:
            cur.append(t)
    segments.append(cur)
    for seg in segments:
        while seg and re.match(r"^[A-Za-z_][A-Za-z0-9_]*=", seg[0]):
            seg = seg[1:]
        if seg and seg[0] == "./hermes":
            yield seg


def options(tokens):
    out = []
    for t in tokens:
        t = t.strip("[](),")
        if t.startswith("--") and len(t) > 2:
            out.append(t.split("=", 1)[0])
    return out


def check_command(cli, tokens):
    """('ok' | 'skip' | 'bad', message)."""
    if len(tokens) < 2:
        return "ok", ""
    sub = tokens[1]
    if sub in ("--help", "-h", "help"):
        return "ok", ""
    if sub not in cli.branches or sub == "*":
        return "bad", "unknown subcommand '%s' (./hermes knows: %s)" % (
            sub, ", ".join(sorted(n for n in cli.branches if n != "*")))
    rest = tokens[2:]
    help_text, skip, err, used = cli.help_for(sub, rest)
    if err:
        return "bad", err
    if skip:
        return "skip", skip
    label = " ".join(tokens[1:2 + used])
    missing = [o for o in options(rest[used:]) if o != "--help"
               and not re.search(r"(?<![\w-])%s(?![\w-])" % re.escape(o), help_text)]
    if missing:
        return "bad", "'./hermes %s --help' does not list %s" % (label, ", ".join(missing))
    return "ok", ""


def main(argv):
    if any(a in ("-h", "--help") for a in argv):
        print(__doc__.strip())
        return 0
    files = argv or [os.path.join(ROOT, "README.md")] + sorted(glob.glob(os.path.join(ROOT, "docs", "*.md")))
    for f in files:
        if not os.path.isfile(f):
            print("check_readme_commands: no file %s" % f, file=sys.stderr)
            return 2
    cli = Cli()
    checked = skipped = bad = 0
    for f in files:
        for no, text in shell_lines(f):
            try:
                commands = list(hermes_commands(text))
            except ValueError as e:
                if "./hermes" in text:
                    print("%s:%d: cannot read the line as shell (%s): %s" % (f, no, e, text.strip()))
                    checked += 1
                    bad += 1
                continue
            for tokens in commands:
                verdict, msg = check_command(cli, tokens)
                shown = " ".join(tokens)
                if verdict == "skip":
                    skipped += 1
                    print("%s:%d: skipped: %s (%s)" % (f, no, msg, shown))
                    continue
                checked += 1
                if verdict == "bad":
                    bad += 1
                    print("%s:%d: %s: %s" % (f, no, msg, shown))
    print("readme commands: %d checked, %d skipped, %d bad" % (checked, skipped, bad))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
