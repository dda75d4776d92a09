#!/usr/bin/env python3
"""Load-and-fault test of `pgrf enhance` batches (issue 37).

Makes N tiny RAWs (64x48 charts of varied exposure, CFA phase and black
level), enhances them once in one uninterrupted run (the reference), then
again as S shards running at the same time, each SIGKILLed at seeded random
points of its progress (after a random number of its files, and a random
few milliseconds) and started again with `--skip-existing --manifest shardI.jsonl`
until it exits 0. Then it checks that:

  - the shards' output folder holds exactly one DNG and one PNG per input
    and nothing else (no `.part` file left by a killed writer);
  - every output is bit-identical to the reference run's;
  - the manifests account for every input: each input's last line in its
    own shard's manifest says done or skipped, no input appears in another
    shard's manifest, and lines that do not parse (cut short by a kill)
    number at most the kills of that shard;

and prints files/s and each process's peak RSS (ru_maxrss from os.wait4).
It exits 1 on any violation, 0 when every check passed.

Python 3 standard library only:

    tools/load_fault.py --pgrf target/release/pgrf              # 1000 files, 4 shards
    tools/load_fault.py --files 40 --shards 4 --kills 6 --pgrf target/debug/pgrf
"""

import argparse
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time

ENHANCE = ["--model", "builtin:spc", "--noise", "K=1,read=4", "--ratio", "10", "--png", "--quiet"]


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--files", type=int, default=1000, help="inputs to make (default 1000)")
    p.add_argument("--shards", type=int, default=4, help="shards run at the same time (default 4)")
    p.add_argument("--kills", type=int, default=12,
                   help="SIGKILLs in all, spread over the shards at random (default 12)")
    p.add_argument("--seed", type=int, default=1, help="seed of the inputs and the kills (default 1)")
    p.add_argument("--pgrf", default="target/release/pgrf", help="the pgrf binary")
    p.add_argument("--keep", action="store_true", help="keep the scratch folder and print its path")
    a = p.parse_args()
    if a.files < 1 or a.shards < 1 or a.kills < 0:
        p.error("--files and --shards must be at least 1, --kills at least 0")
    return a


def run_timed(cmd, cwd):
    """Run cmd to its end: (exit code, seconds, peak RSS in MiB, stderr)."""
    t0 = time.monotonic()
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    err = proc.stderr.read()
    _, status, usage = os.wait4(proc.pid, 0)
    proc.returncode = os.waitstatus_to_exitcode(status)
    return proc.returncode, time.monotonic() - t0, usage.ru_maxrss / 1024.0, err.decode(errors="replace")


def make_inputs(pgrf, work, n, rng):
    """n charts in work/in, and work/list.txt naming them (relative to work,
    with a comment and blank lines, as a user's list would have)."""
    os.mkdir(os.path.join(work, "in"))
    names = []
    for i in range(n):
        name = os.path.join("in", f"c{i:05d}.dng")
        cmd = [pgrf, "chart", "-o", name, "--width", "64", "--height", "48",
               "--exposure", f"{rng.uniform(0.05, 0.95):.4f}",
               "--cfa", rng.choice(["RGGB", "BGGR", "GRBG", "GBRG"]),
               "--black", str(rng.choice([256, 512, 1024]))]
        r = subprocess.run(cmd, cwd=work, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        if r.returncode != 0:
            sys.exit(f"load_fault: {' '.join(cmd)} failed: {r.stderr.decode(errors='replace')}")
        names.append(name)
    order = names[:]
    rng.shuffle(order)  # the list's order must not matter: shards sort it
    with open(os.path.join(work, "list.txt"), "w") as f:
        f.write("# inputs of the load-and-fault test\n\n")
        f.write("\n".join(order) + "\n")
    return names


class Shard:
    """One shard: its current process, the kills still to come, what its
    processes used."""

    def __init__(self, index, count, kills):
        self.index, self.count = index, count
        # (files, seconds): SIGKILL once the manifest has accounted for this
        # many of the shard's files, and this many seconds more have passed.
        self.kills = sorted(kills)
        self.manifest = f"shard{index}.jsonl"
        self.proc = None
        self.attempts = []  # (outcome, seconds, peak RSS MiB)
        self.killed = 0
        self.parts_left = 0  # half-written files the kills left in out/
        self.seen = set()  # inputs the manifest says are done or skipped
        self.read_to = 0  # bytes of the manifest read so far
        self.due = None  # when the next kill is due, once its file count is reached
        self.done = False

    def start(self, pgrf, work):
        cmd = [pgrf, "enhance", "--from-list", "list.txt", "-o", "out", *ENHANCE,
               "--shard", f"{self.index}/{self.count}", "--skip-existing",
               "--manifest", self.manifest]
        self.err = tempfile.TemporaryFile()
        self.proc = subprocess.Popen(cmd, cwd=work, stdout=subprocess.DEVNULL, stderr=self.err)
        self.started = time.monotonic()
        self.due = None

    def progress(self, work):
        """How many of its files the manifest accounts for (whole lines only)."""
        path = os.path.join(work, self.manifest)
        if os.path.exists(path):
            with open(path, "rb") as f:
                f.seek(self.read_to)
                chunk = f.read()
            whole = chunk[: chunk.rfind(b"\n") + 1]
            self.read_to += len(whole)
            for line in whole.splitlines():
                try:
                    rec = json.loads(line)
                except ValueError:
                    continue
                if rec.get("status") in ("done", "skipped"):
                    self.seen.add(rec.get("input"))
        return len(self.seen)

    def kill_now(self, work):
        """Whether the next planned kill is due."""
        if not self.kills:
            return False
        now = time.monotonic()
        if self.due is None and self.progress(work) >= self.kills[0][0]:
            self.due = now + self.kills[0][1]
        return self.due is not None and now >= self.due

    def stderr(self):
        self.err.seek(0)
        return self.err.read().decode(errors="replace").strip()


def run_shards(pgrf, work, shards, problems):
    """Run every shard to exit 0, killing each at its planned points."""
    for s in shards:
        s.start(pgrf, work)
    budget = 3 + max(len(s.kills) for s in shards)
    while not all(s.done for s in shards):
        for s in shards:
            if s.done:
                continue
            if s.kill_now(work):
                s.kills.pop(0)
                try:
                    os.kill(s.proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                _, status, usage = os.wait4(s.proc.pid, 0)
                tag = f".{s.proc.pid}."
                out = os.path.join(work, "out")
                if os.path.isdir(out):
                    s.parts_left += sum(1 for n in os.listdir(out)
                                        if n.startswith(".") and n.endswith(".part") and tag in n)
            else:
                pid, status, usage = os.wait4(s.proc.pid, os.WNOHANG)
                if pid == 0:
                    continue
            code = os.waitstatus_to_exitcode(status)
            seconds = time.monotonic() - s.started
            rss = usage.ru_maxrss / 1024.0
            s.proc.returncode = code
            if code == -signal.SIGKILL:
                s.killed += 1
                s.attempts.append((f"killed at {seconds:.2f} s", seconds, rss))
            elif code == 0:
                s.attempts.append(("exit 0", seconds, rss))
                s.done = True
                continue
            else:
                problems.append(f"shard {s.index}: exit {code}: {s.stderr()}")
                s.attempts.append((f"exit {code}", seconds, rss))
            if len(s.attempts) >= budget:
                problems.append(f"shard {s.index}: not done after {len(s.attempts)} starts")
                s.done = True
                continue
            s.start(pgrf, work)
        time.sleep(0.002)


def check_outputs(work, names, problems):
    want = set()
    for n in names:
        stem = os.path.splitext(os.path.basename(n))[0]
        want |= {stem + ".dng", stem + ".png"}
    got = set(os.listdir(os.path.join(work, "out")))
    for extra in sorted(got - want)[:10]:
        problems.append(f"out/{extra}: not an output of any input")
    for missing in sorted(want - got)[:10]:
        problems.append(f"out/{missing}: missing")
    differ = 0
    for name in sorted(want & got):
        with open(os.path.join(work, "out", name), "rb") as a, \
                open(os.path.join(work, "ref", name), "rb") as b:
            if a.read() != b.read():
                differ += 1
                if differ <= 10:
                    problems.append(f"out/{name}: differs from the reference run's")
    return len(got), differ


def check_manifests(work, names, shards, problems):
    """Each input's last line in its shard's manifest says done or skipped;
    no input in another shard's manifest; torn lines at most one per kill."""
    sorted_names = sorted(names)
    owner = {n: i % len(shards) for i, n in enumerate(sorted_names)}
    final = {}
    torn_total = 0
    for s in shards:
        path = os.path.join(work, f"shard{s.index}.jsonl")
        torn = 0
        with open(path) as f:
            text = f.read()
        if text and not text.endswith("\n"):
            problems.append(f"{path}: the last line of a run that ended with exit 0 is cut short")
        for line in text.splitlines():
            try:
                rec = json.loads(line)
            except json.JSONDecodeError:
                torn += 1
                continue
            inp = rec.get("input")
            if owner.get(inp) != s.index:
                problems.append(f"{path}: {inp} is not shard {s.index}'s")
                continue
            if rec.get("shard") != f"{s.index}/{s.count}":
                problems.append(f"{path}: {inp}: shard {rec.get('shard')!r}")
            final[inp] = rec.get("status")
        if torn > s.killed:
            problems.append(f"{path}: {torn} lines cut short, more than the {s.killed} kills")
        torn_total += torn
    bad = [n for n in sorted_names if final.get(n) not in ("done", "skipped")]
    for n in bad[:10]:
        problems.append(f"{n}: last manifest status {final.get(n)!r}, not done or skipped")
    return torn_total


def main():
    a = parse_args()
    pgrf = os.path.abspath(a.pgrf)
    if not os.access(pgrf, os.X_OK):
        sys.exit(f"load_fault: --pgrf {a.pgrf}: not an executable")
    rng = random.Random(a.seed)
    work = tempfile.mkdtemp(prefix="pgrf-load-fault-")
    problems = []
    try:
        t0 = time.monotonic()
        names = make_inputs(pgrf, work, a.files, rng)
        print(f"{a.files} inputs made in {time.monotonic() - t0:.1f} s ({work})")

        code, ref_s, ref_rss, err = run_timed(
            [pgrf, "enhance", "in", "-o", "ref", *ENHANCE, "--manifest", "ref.jsonl"], work)
        if code != 0:
            sys.exit(f"load_fault: the reference run failed (exit {code}): {err.strip()}")
        print(f"reference: {a.files} files in {ref_s:.1f} s, {a.files / ref_s:.1f} files/s, "
              f"peak RSS {ref_rss:.0f} MiB")

        # Each kill comes once its shard's manifest accounts for a random
        # number of the shard's files, a random few milliseconds later: in
        # the model's loading, a file's restoration, its writes, the checks
        # of files done before a restart, or the manifest's append.
        plan = [[] for _ in range(a.shards)]
        for _ in range(a.kills):
            i = rng.randrange(a.shards)
            mine = len(range(i, a.files, a.shards))
            plan[i].append((rng.randrange(max(1, mine)), rng.uniform(0.0, 0.03)))
        shards = [Shard(i, a.shards, k) for i, k in enumerate(plan)]
        t0 = time.monotonic()
        run_shards(pgrf, work, shards, problems)
        wall = time.monotonic() - t0
        kills = sum(s.killed for s in shards)
        parts = sum(s.parts_left for s in shards)
        print(f"shards: {a.shards} at once, {kills} of {a.kills} planned SIGKILLs landed "
              f"({parts} left a half-written .part file), "
              f"{a.files} files in {wall:.1f} s, {a.files / wall:.1f} files/s")
        for s in shards:
            runs = "; ".join(f"{o}, peak RSS {r:.0f} MiB" for o, _, r in s.attempts)
            print(f"  shard {s.index}/{a.shards}: {len(s.attempts)} starts: {runs}")

        n_out, differ = check_outputs(work, names, problems)
        torn = check_manifests(work, names, shards, problems)
        print(f"checks: {n_out} files in out/ for {a.files} inputs, {differ} differ from the "
              f"reference, {torn} manifest lines cut short by kills")
    finally:
        if a.keep:
            print(f"kept {work}")
        else:
            shutil.rmtree(work, ignore_errors=True)
    if problems:
        for p in problems:
            print(f"VIOLATION: {p}")
        print(f"load_fault: {len(problems)} violations")
        return 1
    print("load_fault: all checks passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
