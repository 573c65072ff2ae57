#!/usr/bin/env bash
# The size of what travels with this checkout: the tracked files and the untracked ones git does
# not ignore (`git ls-files --cached --others --exclude-standard`; tracked files deleted from
# the working tree are skipped), as they are on disk. A copy of that tree is what reaches a GPU
# machine, at most 64 MiB together with a 31 MiB data pack and a checkpoint, so it must stay
# at or below 24 MiB. Prints the total and the 10 largest files; exits 1 above the limit.
#
#   bash scripts/tree-size.sh              # the working tree (CI: a clean clone, so the tracked files)
#   bash scripts/tree-size.sh --commit REV # the files a commit holds, at their committed sizes
#
# .ci/run runs it before the tests.
set -euo pipefail
cd "$(dirname "$0")/.."
exec python3 - "$@" <<'EOF'
import os
import signal
import subprocess
import sys

signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # `| head` ends the listing quietly

LIMIT = 24 * 1024 * 1024  # 25,165,824 bytes


def working_tree():
    out = subprocess.run(
        ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
        check=True, capture_output=True).stdout
    sizes = {}
    for raw in out.split(b"\0"):
        if not raw:
            continue
        path = os.fsdecode(raw)
        try:
            st = os.lstat(path)
        except FileNotFoundError:
            continue  # tracked, deleted in the working tree: it does not travel
        if os.path.isdir(path) and not os.path.islink(path):
            continue  # a submodule's folder (its files travel only when named)
        sizes[path] = st.st_size
    return sizes, "tracked + untracked-not-ignored files of the working tree"


def commit(rev):
    out = subprocess.run(["git", "ls-tree", "-r", "-l", "-z", rev],
                         check=True, capture_output=True).stdout
    sizes = {}
    for raw in out.split(b"\0"):
        if not raw:
            continue
        meta, path = raw.split(b"\t", 1)
        size = meta.split()[3]
        if size != b"-":  # a submodule entry has no size
            sizes[os.fsdecode(path)] = int(size)
    return sizes, f"files of commit {rev}"


args = sys.argv[1:]
if not args:
    sizes, what = working_tree()
elif len(args) == 2 and args[0] == "--commit":
    sizes, what = commit(args[1])
else:
    sys.exit("usage: bash scripts/tree-size.sh [--commit REV]")

total = sum(sizes.values())
mib = lambda n: n / (1024 * 1024)
print(f"{what}: {len(sizes)} files, {total:,} bytes ({mib(total):.2f} MiB); "
      f"limit {LIMIT:,} bytes ({mib(LIMIT):.0f} MiB)")
print("largest:")
for path, size in sorted(sizes.items(), key=lambda kv: (-kv[1], kv[0]))[:10]:
    print(f"  {size:>12,}  {path}")
if total > LIMIT:
    print(f"tree-size: {total:,} bytes is {total - LIMIT:,} bytes over the limit of {LIMIT:,} "
          f"(24 MiB): what travels to a GPU machine must leave room for the data pack and a "
          f"checkpoint within 64 MiB. Remove finished work from the tree with `git rm` (it stays "
          f"in the history) or ignore generated files; see docs/usage.md, 'A small clone'.",
          file=sys.stderr)
    sys.exit(1)
EOF
