#!/usr/bin/env bash
# ./hermes keys: the robots' pre-shared keys for authenticated frames (DESIGN §9).
# One file <ROBOT>.key per robot (64 hex digits = 32 random bytes from
# /dev/urandom, mode 0600) in a folder outside the repository. The server reads
# the whole folder (server.auth.key_dir), each robot its own file
# (uplink.auth.key_file); copy a robot's file to it over a trusted channel.
set -euo pipefail
DIR="${HERMES_KEY_DIR:-$HOME/.config/hermes/keys}"

die() { echo "hermes keys: $*" >&2; exit 2; }

usage() {
  cat <<H
usage: ./hermes keys add ROBOT [--dir DIR] [--force]   create ROBOT's key (an existing one is kept without --force)
       ./hermes keys list [--dir DIR]                  robots with a key, with a fingerprint (never the key)
       ./hermes keys remove ROBOT [--dir DIR]          delete ROBOT's key (the server refuses it after a restart)

  ROBOT is the agent's name (launch argument robot:=ROBOT, offline runner: the
  dataset folder name): letters, digits, '_' and '-'.
  DIR defaults to \$HERMES_KEY_DIR or ~/.config/hermes/keys (now: $DIR).
H
}

valid_robot() { [[ "$1" =~ ^[A-Za-z0-9_-]+$ ]] || die "robot name '$1' must be letters, digits, '_' or '-'"; }

fingerprint() { printf '%s' "$(tr -d ' \n\r' <"$1")" | sha256sum | cut -c1-16; }

cmd_add() {
  local robot="" force=0
  while [[ $# -gt 0 ]]; do
    case "$1" in
      --dir) [[ $# -ge 2 ]] || die "--dir needs a folder"; DIR="$2"; shift 2 ;;
      --force) force=1; shift ;;
      -*) die "add: unknown option $1" ;;
      *) [[ -z "$robot" ]] || die "add: one robot at a time"; robot="$1"; shift ;;
    esac
  done
  [[ -n "$robot" ]] || die "add: which robot? (./hermes keys add ROBOT)"
  valid_robot "$robot"
  local file="$DIR/$robot.key"
  if [[ -e "$file" && $force -eq 0 ]]; then  # idempotent: an existing key is kept
    echo "$file  (fingerprint $(fingerprint "$file")) exists, kept; --force replaces it (the robot then needs the new file)"
    return 0
  fi
  umask 077
  mkdir -p "$DIR" || die "cannot create $DIR"
  chmod 700 "$DIR"
  local tmp
  tmp="$(mktemp "$DIR/.$robot.XXXXXX")"
  head -c 32 /dev/urandom | od -An -v -tx1 | tr -d ' \n' >"$tmp"
  echo >>"$tmp"
  [[ "$(tr -d '\n' <"$tmp" | wc -c)" -eq 64 ]] || { rm -f "$tmp"; die "could not read 32 bytes from /dev/urandom"; }
  chmod 600 "$tmp"
  mv -f "$tmp" "$file"
  echo "$file  (fingerprint $(fingerprint "$file"))"
}

cmd_list() {
  while [[ $# -gt 0 ]]; do
    case "$1" in
      --dir) [[ $# -ge 2 ]] || die "--dir needs a folder"; DIR="$2"; shift 2 ;;
      *) die "list: unknown argument $1" ;;
    esac
  done
  [[ -d "$DIR" ]] || die "no key folder $DIR (create a key with ./hermes keys add ROBOT)"
  local f n=0 note
  for f in "$DIR"/*.key; do
    [[ -e "$f" ]] || continue
    note=""
    [[ "$(stat -c %a "$f")" == 600 ]] || note="  NOT PRIVATE: chmod 600 $f"
    [[ "$(tr -d '\n\r ' <"$f")" =~ ^[0-9a-fA-F]{64}$ ]] || note="$note  MALFORMED: not 64 hex digits"
    printf '%-24s %s%s\n' "$(basename "$f" .key)" "$(fingerprint "$f")" "$note"
    n=$((n + 1))
  done
  echo "$n key(s) in $DIR" >&2
}

cmd_remove() {
  local robot=""
  while [[ $# -gt 0 ]]; do
    case "$1" in
      --dir) [[ $# -ge 2 ]] || die "--dir needs a folder"; DIR="$2"; shift 2 ;;
      -*) die "remove: unknown option $1" ;;
      *) robot="$1"; shift ;;
    esac
  done
  [[ -n "$robot" ]] || die "remove: which robot?"
  valid_robot "$robot"
  [[ -f "$DIR/$robot.key" ]] || die "no key for $robot in $DIR"
  rm -f "$DIR/$robot.key"
  echo "removed $DIR/$robot.key"
}

for a in "$@"; do  # --help anywhere (e.g. ./hermes keys add --help): the usage, nothing else
  [[ "$a" == --help || "$a" == -h ]] && { usage; exit 0; }
done
sub="${1:-}"
[[ $# -gt 0 ]] && shift
case "$sub" in
  add) cmd_add "$@" ;;
  list) cmd_list "$@" ;;
  remove) cmd_remove "$@" ;;
  ""|--help|-h|help) usage ;;
  *) usage >&2; die "unknown subcommand '$sub'" ;;
esac
