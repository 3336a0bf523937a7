#!/usr/bin/env python3
"""Journal damage, end to end (issue 56 item 6): `arbor serve` journals a dataset published over
a loopback tcpq hub, then restarts (--no-refine) on damaged copies of the journal and on copies
with exactly the damaged events removed, and prints each restart's exit status, journal_edges,
F_final and faults.journal_damaged, and whether F equals the reference's.

Cases: an edge's seq changed to 2^56 + 546 (its high byte), an edge's data length set to
0x7FFFFFFF, 4 and 3,000 junk bytes after the last event (the exit refinement's mark), a value
byte of an edge; then --random N trials, alternately a changed byte and a cut at a random offset
(only mismatches are printed). --old ARBOR runs the named cases with another binary too (no
reference: it shows what that binary does with the same damage).

usage: scripts/journal_damage.py build/tools/arbor [--old OLD_ARBOR] [--data M3500.g2o]
                                 [--random 1000] [--work DIR]
"""
import argparse
import json
import os
import random
import shutil
import signal
import socket
import struct
import subprocess
import tempfile
import time

SYNC = b"\xed\xa1\xda\x01"


def free_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def events(b):
    """(start, end, channel, data offset) of every event of an undamaged journal."""
    out, at = [], 0
    while at < len(b):
        assert b[at:at + 4] == SYNC, f"not an event at {at}"
        channel_bytes, data_bytes = struct.unpack(">ii", b[at + 20:at + 28])
        end = at + 28 + channel_bytes + data_bytes
        out.append((at, end, b[at + 28:at + 28 + channel_bytes].decode(), at + 28 + channel_bytes))
        at = end
    return out


class Runner:
    def __init__(self, work, url, data):
        self.work, self.url, self.data = work, url, data

    def serve(self, exe, journal_dir, name, publish=False, extra=()):
        """Runs serve on journal_dir (publishing the dataset, or only replaying), stops it with
        SIGINT; (exit status, its JSON or None)."""
        err_path = os.path.join(self.work, name + ".err")
        with open(err_path, "w") as err:
            p = subprocess.Popen([exe, "serve", "--lcm-url", self.url, "--journal", journal_dir,
                                  "--json", "--status-period", "0.2", *extra],
                                 stdout=subprocess.PIPE, stderr=err, text=True)
            if publish:
                r = subprocess.run([exe, "publish", self.data, "--lcm-url", self.url,
                                    "--wait-ready", "--wait", "--timeout", "120", "--json"],
                                   capture_output=True, text=True)
                assert r.returncode == 0, r.stderr
            else:  # until the replay's summary line (none for an empty journal: 5 s at most)
                for _ in range(50):
                    if p.poll() is not None or "to apply" in open(err_path).read():
                        break
                    time.sleep(0.1)
            if p.poll() is None:
                p.send_signal(signal.SIGINT)
            out, _ = p.communicate(timeout=600)
        try:
            return p.returncode, json.loads(out)
        except ValueError:
            return p.returncode, None

    def restart(self, exe, journal_bytes, name):
        d = os.path.join(self.work, name)
        shutil.rmtree(d, ignore_errors=True)
        os.makedirs(d)
        with open(os.path.join(d, "journal.lcmlog"), "wb") as f:
            f.write(journal_bytes)
        return self.serve(exe, d, name, extra=["--no-refine"])


def summary(rc, j):
    if j is None:
        return f"exit {rc}, no JSON"
    damaged = j.get("faults", {}).get("journal_damaged")
    return (f"exit {rc}, journal_edges {j['journal_edges']}, F {j['F_final']:.6f}" +
            (f", journal_damaged {damaged}" if damaged is not None else ""))


def main():
    here = os.path.dirname(os.path.abspath(__file__))
    ap = argparse.ArgumentParser()
    ap.add_argument("arbor")
    ap.add_argument("--old")
    ap.add_argument("--data", default=os.path.join(here, "../../shared/datasets/M3500.g2o"))
    ap.add_argument("--random", type=int, default=0)
    ap.add_argument("--work")
    a = ap.parse_args()
    work = a.work or tempfile.mkdtemp(prefix="arbor_journal_damage_")
    port = free_port()
    hub = subprocess.Popen(["java", "-cp", "/usr/share/java/lcm.jar", "lcm.lcm.TCPService",
                            str(port)], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        for _ in range(300):
            try:
                socket.create_connection(("127.0.0.1", port), 0.2).close()
                break
            except OSError:
                time.sleep(0.1)
        run = Runner(work, f"tcpq://127.0.0.1:{port}", a.data)
        live_dir = os.path.join(work, "live")
        rc, j = run.serve(a.arbor, live_dir, "live", publish=True)
        print(f"live: {summary(rc, j)}")
        clean = open(os.path.join(live_dir, "journal.lcmlog"), "rb").read()
        ev = events(clean)
        edges = [k for k, e in enumerate(ev) if e[2].endswith("ARBOR_EDGES")]
        print(f"journal: {len(ev)} events, {len(edges)} edges, the last on {ev[-1][2]}")

        def without(lost):
            return b"".join(clean[s:e] for k, (s, e, _, _) in enumerate(ev) if k not in lost)

        rng = random.Random(56)
        cases = []
        k = edges[min(545, len(edges) - 1)]
        b = bytearray(clean)
        b[ev[k][3] + 24] ^= 1  # edge_t: hash, utime, sender, seq (its high byte)
        cases.append((f"edge {edges.index(k) + 1}'s seq + 2^56", bytes(b), {k}))
        k = edges[len(edges) // 2]
        b = bytearray(clean)
        b[ev[k][0] + 24:ev[k][0] + 28] = b"\x7f\xff\xff\xff"
        cases.append(("a data length of 0x7FFFFFFF", bytes(b), {k}))
        for size in (4, 3000):
            junk = bytes(rng.randrange(256) for _ in range(size))
            cases.append((f"{size} junk bytes after the last event", clean + junk, set()))
        k = edges[min(1000, len(edges) - 1)]
        b = bytearray(clean)
        b[ev[k][3] + 60] ^= 0x40  # a byte of its translation
        cases.append(("a value byte of an edge", bytes(b), {k}))

        for label, exe in (("new", a.arbor), ("old", a.old)):
            if exe is None:
                continue
            print(f"[{label}] undamaged: {summary(*run.restart(exe, clean, 'undamaged'))}")
            for what, damaged, lost in cases:
                rc, j = run.restart(exe, damaged, "damaged")
                line = f"[{label}] {what}: {summary(rc, j)}"
                if label == "new":
                    rc2, j2 = run.restart(exe, without(lost), "reference")
                    same = j is not None and j2 is not None and j["F_final"] == j2["F_final"]
                    line += f" | without the {len(lost)} damaged: {summary(rc2, j2)}; F equal: {same}"
                print(line, flush=True)

        mismatches = 0
        for t in range(a.random):
            if t % 2 == 0:
                at = rng.randrange(len(clean))
                b = bytearray(clean)
                b[at] ^= rng.randrange(1, 256)
                lost, what = {k for k, e in enumerate(ev) if e[0] <= at < e[1]}, f"byte {at}"
            else:
                at = rng.randrange(len(clean))
                b = clean[:at]
                lost, what = {k for k, e in enumerate(ev) if e[1] > at}, f"cut at {at}"
            rc, j = run.restart(a.arbor, bytes(b), "random")
            rc2, j2 = run.restart(a.arbor, without(lost), "random_reference")
            if not (rc == 0 and j and j2 and j["F_final"] == j2["F_final"] and
                    j["journal_edges"] == j2["journal_edges"]):
                mismatches += 1
                print(f"MISMATCH {what}: {summary(rc, j)} vs {summary(rc2, j2)}", flush=True)
        if a.random:
            print(f"random: {a.random} trials (changed bytes and cuts), {mismatches} mismatches")
    finally:
        hub.kill()
        hub.wait()
        if not a.work:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
