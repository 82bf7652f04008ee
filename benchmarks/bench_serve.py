"""Live service under load: a real WebSocket client sends 20 blocks a second for 30 s to ``agentsim serve``
(each a speech with a beat on a word and a nod, espeak-ng timing them), and every second one speech is
interrupted while it plays.

Prints JSON: the lateness of every timed feedback (arrival on the client minus the moment its
``globalTime`` stands for on the server's clock; p50, p95, max, and the spread max - min), the interrupt
latency (from sending a ``bmla:interrupt`` to the arrival of the interrupted speech's end; p50, p95, max),
how many blocks ran and how many the server refused. Targets: lateness spread within 20 ms, interrupt
latency within 100 ms.

    python benchmarks/bench_serve.py [SECONDS] [BLOCKS_PER_SECOND] [--audio DEVICE] [--fps N]

    python benchmarks/bench_serve.py SECONDS --slow-readers N

The slow-readers case: ``N`` clients (bare sockets, their buffers as the system makes them) subscribe to the
poses (30 fps) and then read nothing for ``SECONDS``; prints the server's RSS before, during (every second; the
peak) and after, a fresh client's connection and block latency before, during and after (the time from
sending a block to its start feedback, and its feedback's lateness spread), and when the server closed the
slow readers. Target: RSS within 50 MB of the baseline, the fresh client's latency within 1.5 times its own
before.

With ``--audio`` the speech also plays on that device and feedback waits for it to be heard (the lateness
then centres on the service's ``delay_ms``, printed too); with ``--fps`` a viewer's poses are evaluated and
streamed as well (a client subscribes to them).
"""

from __future__ import annotations

import argparse
import json
import os
import threading
import time
from pathlib import Path

import numpy as np
from websockets.sync.client import connect

from agentsim.live.service import Background, Service
from speech_timing.espeak import EspeakBackend

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0" xmlns:bmla="http://www.asap-project.org/bmla"'


def block(i: int) -> str:
    return (f'<bml {NS} id="b{i}"><speech id="s"><text>Block {i} says <sync id="w"/>hello to you.</text></speech>'
            f'<gesture id="g" lexeme="BEAT" stroke="s:w"/><head id="h" lexeme="NOD" start="s:end"/></bml>')


def rss_mb() -> float:
    """This process's resident memory (the server runs in it), in MB."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def fresh_client(url: str, live, name: str) -> dict:
    """A new client connects and runs a short block: connection time, the time from sending the block to its
    start feedback, and the lateness spread of its feedback (ms)."""
    started = time.monotonic()
    with connect(url, open_timeout=10, max_size=2 ** 22) as ws:
        connected = time.monotonic()
        ws.send(f'<bml {NS} id="{name}"><wait id="w" start="0" end="0.6"/>'
                + "".join(f'<head id="h{i}" lexeme="NOD" start="{0.1 * i:.1f}"/>' for i in range(6)) + "</bml>")
        sent = time.monotonic()
        first, lateness = None, []
        deadline = sent + 10
        while time.monotonic() < deadline:
            item = json.loads(ws.recv(timeout=deadline - time.monotonic()))
            arrival = time.monotonic()
            if "id" not in item:
                continue
            if item["type"] in ("syncPointProgress", "blockProgress"):
                lateness.append(arrival - live.wall_time(item["globalTime"]))
            if first is None and item["id"] == f"{name}:start":
                first = arrival - sent
            if item["id"] == f"{name}:end":
                break
    return {"connect_ms": round(1000 * (connected - started), 2),
            "start_ms": round(1000 * first, 2) if first is not None else None,
            "lateness_spread_ms": round(1000 * float(np.ptp(lateness)), 2) if lateness else None}


def slow_readers(seconds: float, n: int) -> dict:
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    from rawws import RawClient

    with Background(Service(port=0, audio="none", fps=30.0, tts=EspeakBackend())) as service:
        live, server = service.service.live, service.service.server
        fresh_client(service.url, live, "warm")
        time.sleep(1.0)
        before = {"rss_mb": round(rss_mb(), 1), "fresh": [fresh_client(service.url, live, f"a{i}") for i in range(3)]}
        clients = []
        for _ in range(n):
            client = RawClient(service.url)
            client.send(json.dumps({"subscribe": "poses"}))
            clients.append(client)
        started = time.monotonic()
        samples, fresh, closes = [], [], []
        k = 0
        while time.monotonic() - started < seconds:
            samples.append((round(time.monotonic() - started, 1), round(rss_mb(), 1)))
            closed = server.counters["closed_not_reading"]
            if len(closes) < closed:
                closes.extend([round(time.monotonic() - started, 1)] * (closed - len(closes)))
            if k % 10 == 5:
                fresh.append({"at_s": samples[-1][0], **fresh_client(service.url, live, f"d{k}")})
            k += 1
            time.sleep(max(0.0, started + k - time.monotonic()))
        for client in clients:
            client.close()
        counters = dict(server.counters)
        time.sleep(3.0)
        after = {"rss_mb": round(rss_mb(), 1), "fresh": [fresh_client(service.url, live, f"z{i}") for i in range(3)]}

    def median(values):
        values = [v for v in values if v is not None]
        return round(float(np.median(values)), 2) if values else None

    return {
        "benchmark": "serve-slow-readers", "slow_readers": n, "seconds": seconds,
        "load_average": [round(x, 2) for x in os.getloadavg()],
        "rss_mb": {"before": before["rss_mb"], "peak_during": max(r for _, r in samples),
                   "end_of_during": samples[-1][1], "after": after["rss_mb"]},
        "rss_samples": samples,
        "fresh_client": {
            "before": {"start_ms_median": median(f["start_ms"] for f in before["fresh"]),
                       "connect_ms_median": median(f["connect_ms"] for f in before["fresh"]), "runs": before["fresh"]},
            "during": {"start_ms_median": median(f["start_ms"] for f in fresh),
                       "start_ms_max": max((f["start_ms"] for f in fresh if f["start_ms"] is not None), default=None),
                       "connect_ms_median": median(f["connect_ms"] for f in fresh),
                       "connect_ms_max": max(f["connect_ms"] for f in fresh) if fresh else None, "runs": fresh},
            "after": {"start_ms_median": median(f["start_ms"] for f in after["fresh"]),
                      "connect_ms_median": median(f["connect_ms"] for f in after["fresh"]), "runs": after["fresh"]}},
        "slow_readers_closed_at_s": closes,
        "counters": counters,
        "targets": {"rss_above_baseline_mb": 50, "fresh_latency_ratio": 1.5},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description="agentsim serve under a load of blocks")
    parser.add_argument("seconds", nargs="?", type=float, default=30.0)
    parser.add_argument("rate", nargs="?", type=float, default=20.0, help="blocks per second")
    parser.add_argument("--audio", default="none", help="output device for the speech (none)")
    parser.add_argument("--fps", type=float, default=0.0, help="poses per second for a subscribed viewer (0)")
    parser.add_argument("--slow-readers", type=int, default=0, metavar="N",
                        help="instead: N clients that subscribe to the poses and read nothing for SECONDS")
    args = parser.parse_args()
    if args.slow_readers:
        print(json.dumps(slow_readers(args.seconds, args.slow_readers), indent=2))
        return
    seconds, rate = args.seconds, args.rate
    with Background(Service(port=0, audio=args.audio, fps=args.fps, tts=EspeakBackend())) as service:
        live = service.service.live
        arrivals: list[tuple[float, dict]] = []
        done = threading.Event()

        with connect(service.url, max_size=2 ** 22) as ws:
            if args.fps > 0:
                ws.send(json.dumps({"subscribe": "poses"}))
            def listen():
                while not done.is_set():
                    try:
                        message = ws.recv(timeout=0.2)
                    except TimeoutError:
                        continue
                    except Exception:
                        return
                    item = json.loads(message)
                    if "id" in item:  # feedback, not poses
                        arrivals.append((time.monotonic(), item))

            listener = threading.Thread(target=listen, daemon=True)
            listener.start()
            interrupts: dict[str, float] = {}
            started = time.monotonic()
            n = int(seconds * rate)
            for i in range(n):
                due = started + i / rate
                time.sleep(max(0.0, due - time.monotonic()))
                ws.send(block(i))
                if i % int(rate) == int(rate) // 2 and i >= rate:  # interrupt a speech that is playing
                    target = f"b{i - int(rate) // 2}"
                    interrupts[target] = time.monotonic()
                    ws.send(f'<bml {NS} id="x{i}"><bmla:interrupt id="i" target="{target}"/></bml>')
            time.sleep(5.0)
            done.set()
            listener.join(2.0)

        timed = [(a, f) for a, f in arrivals if f["type"] in ("syncPointProgress", "blockProgress")]
        lateness = np.array([a - live.wall_time(f["globalTime"]) for a, f in timed]) * 1000.0
        worst = sorted(zip(lateness, (f["globalTime"] for _, f in timed), (f["id"] for _, f in timed)))[-5:]
        ends = {f["id"][:-len(":s:end")]: a for a, f in arrivals if f["type"] == "syncPointProgress"
                and f["id"].endswith(":s:end")}
        latency = np.array([ends[b] - t for b, t in interrupts.items() if b in ends]) * 1000.0
        ran = sum(1 for _, f in arrivals if f["type"] == "blockProgress" and f["id"].endswith(":end")
                  and f["id"].startswith("b"))
        refused = sum(1 for _, f in arrivals if f["type"] == "warningFeedback" and "already waiting" in f["description"])

        def summary(values: np.ndarray) -> dict:
            if values.size == 0:
                return {"n": 0}
            return {"n": int(values.size), "p50_ms": round(float(np.percentile(values, 50)), 2),
                    "p95_ms": round(float(np.percentile(values, 95)), 2), "max_ms": round(float(values.max()), 2),
                    "min_ms": round(float(values.min()), 2)}

        result = {
            "benchmark": "serve", "seconds": seconds, "blocks_per_second": rate, "audio": args.audio,
            "fps": args.fps, "delay_ms": round(1000 * service.service.server.delay, 2),
            "load_average": [round(x, 2) for x in os.getloadavg()], "blocks_sent": n,
            "blocks_ran": ran, "refused": refused, "feedback_received": len(arrivals),
            "lateness": {**summary(lateness), "spread_ms": round(float(np.ptp(lateness)), 2) if lateness.size else None},
            "interrupt_latency": summary(latency),
            "latest": [{"lateness_ms": round(float(x), 2), "globalTime": round(g, 3), "id": i} for x, g, i in worst],
            "targets": {"lateness_spread_ms": 20, "interrupt_latency_ms": 100},
            "poses": service.service.poses.cost() if service.service.poses is not None else None,
            "sound": None if service.service.sound is None else {
                "underruns": service.service.sound.underruns, "errors": service.service.sound.errors,
                "late_sounds": len(service.service.sound.late)},
        }
        print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
