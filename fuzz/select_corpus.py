#!/usr/bin/env python3
"""Adds the fuzz-found inputs that cover the most new edges to fuzz/corpus/<target>/.

Usage (from the repository root, after a run that fuzzed into /tmp/fz/<target>):

    RUSTC_BOOTSTRAP=1 cargo fuzz run --target-dir $HOME/.cache/fusepose/fuzz-target/cf <target> \\
        /tmp/empty_<target> fuzz/corpus/<target> /tmp/fz/<target> -- \\
        -merge=1 -use_counters=0 -use_value_profile=0 -merge_control_file=/tmp/ctl_<target>.ctl
    python3 fuzz/select_corpus.py <target> /tmp/ctl_<target>.ctl [max_files=50] [max_bytes=200000]

The seeds already in fuzz/corpus/<target>/ are kept; found inputs (40-hex-digit
names) are added greedily by edges not yet covered, until the file or byte
budget is reached or nothing adds an edge.
"""
import os
import re
import shutil
import sys

target, ctl = sys.argv[1], sys.argv[2]
max_files = int(sys.argv[3]) if len(sys.argv) > 3 else 50
max_bytes = int(sys.argv[4]) if len(sys.argv) > 4 else 200_000
lines = open(ctl).read().split("\n")
n = int(lines[0])
files = lines[2 : 2 + n]
cov = {}
for line in lines[2 + n :]:
    if line.startswith("COV "):
        parts = line.split()
        cov[int(parts[1])] = set(map(int, parts[2:]))
corpus = os.path.join(os.path.dirname(os.path.abspath(__file__)), "corpus", target)
kept = set(os.listdir(corpus))
covered = set()
for i, f in enumerate(files):
    if os.path.basename(f) in kept:
        covered |= cov.get(i, set())
total = sum(os.path.getsize(os.path.join(corpus, k)) for k in kept)
count = len(kept)
cands = {i for i, f in enumerate(files)
         if re.fullmatch("[0-9a-f]{40}", os.path.basename(f)) and os.path.basename(f) not in kept}
while count < max_files and cands:
    best = max(cands, key=lambda i: (len(cov.get(i, set()) - covered), -os.path.getsize(files[i])))
    cands.discard(best)
    if not cov.get(best, set()) - covered:
        break
    name, size = os.path.basename(files[best]), os.path.getsize(files[best])
    if name in kept or total + size > max_bytes:
        continue
    shutil.copy(files[best], os.path.join(corpus, name))
    covered |= cov[best]
    kept.add(name)
    total += size
    count += 1
print(f"{target}: {count} files, {total} bytes, {len(covered)} of {len(set().union(*cov.values()))} edges")
