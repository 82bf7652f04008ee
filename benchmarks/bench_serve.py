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

The slow-readers case: ``N`` clients (bare sockets, their buffers as the system makes them, in a process of their
own) subscribe to the poses (30 fps) and then read nothing; each one the server closes is replaced by a new one, so that ``N`` are
there for all of ``SECONDS``; prints the server's RSS before, during (every second; the
peak) and after, a fresh client's connection and block latency before, during and after (the time from
sending a block to its start feedback, and its feedback's lateness spread), and when the server closed the
slow readers. Targets: RSS (its peak during, and after) within 50 MB of the baseline, the fresh client's
latency (connection and block start together, median during) within 1.5 times its own before (median of 9
runs); ``holds`` says whether each does.

    python benchmarks/bench_serve.py --duration 300 --slow-readers 20
    python benchmarks/bench_serve.py SECONDS --churn 200
    python benchmarks/bench_serve.py --large-speech 4

``--duration`` gives SECONDS as an option. The churn case: ``N`` clients (in a process of their own) that for SECONDS
connect (one connection in four subscribes to the poses), send a block, read its feedback for 1 to 5 s and
leave, over and over; prints their handshake times, the server's RSS and a fresh client's latency
before, during and after, and whether the server forgot every client. The large-speech case: ``N`` messages
of a 10,000-word speech each (some 60 kB, an hour of speech), first under the default limits (refused), then
with limits raised to take them (synthesised, started, interrupted and ended); prints the RSS before, at its
peak and after each part, the audio the server held and released, and a fresh client's latency meanwhile.
Target: RSS within 100 MB of the baseline once they have ended (``holds``). The churn case's ``holds`` says
whether every client was forgotten. Every case prints JSON.

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
    try:
        return _fresh_client(url, live, name, started)
    except TimeoutError:  # said in the figures: the client had nothing within 10 s
        return {"connect_ms": None, "start_ms": None, "lateness_spread_ms": None, "timed_out": True,
                "waited_ms": round(1000 * (time.monotonic() - started), 2)}


def _fresh_client(url: str, live, name: str, started: float) -> dict:
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


def median(values):
    values = [v for v in values if v is not None]
    if not values:
        return None
    middle = float(np.median(values))
    return round(middle, 2) if np.isfinite(middle) else None


def fresh_summary(runs: list[dict]) -> dict:
    """A fresh client's runs summarised: its connection time, the time from sending its block to the block's
    start feedback, and the two together (``latency_ms``: what the targets compare; a run that timed out
    counts as infinitely late)."""
    started = [f["start_ms"] for f in runs if f["start_ms"] is not None]
    connected = [f["connect_ms"] for f in runs if f["connect_ms"] is not None]
    latency = [f["connect_ms"] + f["start_ms"] if f["start_ms"] is not None and f["connect_ms"] is not None
               else float("inf") for f in runs]
    worst = max(latency, default=None)
    if worst is not None:
        worst = round(worst, 2) if np.isfinite(worst) else "a run had no start feedback"
    return {"latency_ms_median": median(latency), "latency_ms_max": worst,
            "start_ms_median": median(started), "start_ms_max": max(started, default=None),
            "connect_ms_median": median(connected), "connect_ms_max": max(connected, default=None),
            "timed_out": sum(1 for f in runs if f.get("timed_out")), "runs": runs}


def latency_ratio(during: dict, before: dict) -> float | None:
    """A fresh client's median connection-and-block latency during a load over its median before it."""
    if not during.get("latency_ms_median") or not before.get("latency_ms_median"):
        return None
    return round(during["latency_ms_median"] / before["latency_ms_median"], 2)


class Watch:
    """Samples the server's RSS every second and has a fresh client run a block every ``every`` s, while
    something goes on (``with Watch(service, "d") as watch: ...``)."""

    def __init__(self, service, prefix: str, every: float = 10.0):
        self.service, self.prefix, self.every = service, prefix, every
        self.samples: list[tuple[float, float]] = []
        self.fresh: list[dict] = []
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self.run, daemon=True)

    def run(self) -> None:
        started = time.monotonic()
        k = 0
        while not self.stop.is_set():
            at = round(time.monotonic() - started, 1)
            self.samples.append((at, round(rss_mb(), 1)))
            if k % int(self.every) == 1:
                self.fresh.append({"at_s": at, **fresh_client(self.service.url, self.service.service.live,
                                                              f"{self.prefix}{k}")})
            k += 1
            self.stop.wait(max(0.0, started + k - time.monotonic()))

    def __enter__(self) -> "Watch":
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop.set()
        self.thread.join(30)

    def summary(self) -> dict:
        return {"rss_mb_peak": max((r for _, r in self.samples), default=None),
                "rss_mb_end": self.samples[-1][1] if self.samples else None, "rss_samples": self.samples[::5],
                "fresh": fresh_summary(self.fresh)}


def settled(service, prefix: str, runs: int = 9) -> dict:
    """The RSS and a fresh client's latency with nothing else going on."""
    live = service.service.live
    return {"rss_mb": round(rss_mb(), 1),
            "fresh": fresh_summary([fresh_client(service.url, live, f"{prefix}{i}") for i in range(runs)])}


def churning_clients(url: str, n: int, seconds: float, out) -> None:
    """``n`` clients, each in a thread of its own, that for ``seconds`` connect (one connection in four subscribes to
    the poses), send a block (a nod), hear its feedback, read what comes for 1 to 5 s (seeded) and
    leave, over and over; in a process
    of its own (the server's RSS is then the server's alone). Puts (handshake times, errors) on ``out``."""
    handshakes, errors = [], []
    deadline = time.monotonic() + seconds

    def client(i: int) -> None:
        rng = np.random.default_rng([25, i])
        k = 0
        while time.monotonic() < deadline:
            try:
                t0 = time.monotonic()
                with connect(url, open_timeout=10, max_size=2 ** 22) as ws:
                    handshakes.append(time.monotonic() - t0)
                    if k % 4 == 0:
                        ws.send(json.dumps({"subscribe": "poses"}))
                    ws.send(f'<bml {NS} id="c{i}_{k}"><head id="h" lexeme="NOD"/></bml>')
                    leave = time.monotonic() + rng.uniform(1.0, 5.0)
                    while time.monotonic() < leave:
                        try:
                            ws.recv(timeout=max(0.01, leave - time.monotonic()))
                        except TimeoutError:
                            break
            except Exception as exc:
                errors.append(f"{type(exc).__name__}: {exc}")
            k += 1

    threads = [threading.Thread(target=client, args=(i,), daemon=True) for i in range(n)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    out.put((handshakes, errors))


def churn(seconds: float, n: int) -> dict:
    """``n`` clients connecting and disconnecting for ``seconds``."""
    import multiprocessing

    with Background(Service(port=0, audio="none", fps=30.0, tts=EspeakBackend())) as service:
        server = service.service.server
        fresh_client(service.url, service.service.live, "warm")
        time.sleep(1.0)
        before = settled(service, "a")
        context = multiprocessing.get_context("spawn")
        out = context.Queue()
        clients = context.Process(target=churning_clients, args=(service.url, n, seconds, out))
        with Watch(service, "d", every=5.0) as watch:
            clients.start()
            handshakes, errors = out.get(timeout=seconds + 120)
            clients.join(30)
            time.sleep(2.0)
        during = watch.summary()
        time.sleep(3.0)
        after = settled(service, "z")
        counters = dict(server.counters)
        routing = server.routing
        left = {"clients": len(routing.clients), "outboxes": len(routing.outboxes),
                "subscribers": len(routing.subscribers)}
    ms = np.array(handshakes) * 1000.0
    return {
        "benchmark": "serve-churn", "clients": n, "seconds": seconds, "connections": len(handshakes),
        "client_errors": len(errors), "client_error_kinds": sorted(set(e.split(":")[0] for e in errors)),
        "load_average": [round(x, 2) for x in os.getloadavg()],
        "handshake_ms": {"p50": round(float(np.percentile(ms, 50)), 2), "p95": round(float(np.percentile(ms, 95)), 2),
                         "max": round(float(ms.max()), 2)} if ms.size else None,
        "rss_mb": {"before": before["rss_mb"], "peak_during": during["rss_mb_peak"], "after": after["rss_mb"]},
        "rss_samples": during["rss_samples"],
        "fresh_client": {"before": before["fresh"], "during": during["fresh"], "after": after["fresh"]},
        "left_behind_after": left, "counters": counters,
        "latency_ratio_during": latency_ratio(during["fresh"], before["fresh"]),
        "latency_ratio_after": latency_ratio(after["fresh"], before["fresh"]),
        "targets": {"every_client_forgotten": True},
        "holds": {"every_client_forgotten": not any(left.values())},
    }


def ten_thousand_words(seed: int) -> str:
    """A 10,000-word text of ordinary words, in sentences (some 60 kB)."""
    words = ("the keeper of a lighthouse walked up hill at night and counted ships that passed by on "
             "sea while wind blew over rocks near his small house with old lamp").split()
    rng = np.random.default_rng(seed)
    picked = rng.choice(words, size=10_000)
    sentences = [" ".join(picked[i:i + 12]).capitalize() + "." for i in range(0, 10_000, 12)]
    return " ".join(sentences)


def large_speech(n: int) -> dict:
    """``n`` messages of a 10,000-word speech each: refused under the default limits; taken under raised ones,
    started, interrupted and ended."""
    from agentsim.live.limits import Limits

    with Background(Service(port=0, audio="none", fps=0, tts=EspeakBackend())) as service:
        live = service.service.live
        fresh_client(service.url, live, "warm")
        time.sleep(1.0)
        before = settled(service, "a")
        texts = [ten_thousand_words(i) for i in range(n)]
        parts = {}
        for part, limits in (("default_limits", Limits()),
                             ("raised_limits", Limits(speech_characters=100_000, speech_seconds=10_000,
                                                      block_characters=100_000, block_seconds=10_000))):
            service.service.intake.limits = limits
            started = time.monotonic()
            held, warnings, ended = [], [], set()
            with Watch(service, part[0]) as watch, connect(service.url, max_size=2 ** 22) as ws:
                for i, text in enumerate(texts):
                    ws.send(f'<bml {NS} id="{part}{i}"><speech id="s1"><text>{text}</text></speech></bml>')
                started_ids = set()
                deadline = time.monotonic() + 900
                while len(ended) + len(warnings) < n and time.monotonic() < deadline:
                    try:
                        item = json.loads(ws.recv(timeout=1.0))
                    except TimeoutError:
                        continue
                    block_id = str(item.get("id", "")).split(":")[0]
                    if item.get("type") == "warningFeedback" and item["description"].startswith("block refused"):
                        warnings.append(item["description"])
                    elif item.get("id") == f"{block_id}:s1:start" and block_id not in started_ids:
                        started_ids.add(block_id)
                        held.append(live.audio_bytes)
                        time.sleep(1.0)
                        ws.send(f'<bml {NS} id="x{block_id}"><bmla:interrupt id="i" target="{block_id}"/></bml>')
                    elif item.get("id") == f"{block_id}:end" and block_id.startswith(part):
                        ended.add(block_id)
                time.sleep(2.0)
            during = watch.summary()
            time.sleep(3.0)
            parts[part] = {"seconds": round(time.monotonic() - started, 1), "refused": len(warnings),
                           "warnings": sorted(set(warnings)), "ended": len(ended),
                           "audio_mb_held_at_starts": [round(b / 2 ** 20, 1) for b in held],
                           "audio_mb_held_after": round(live.audio_bytes / 2 ** 20, 1),
                           "audio_mb_released": round(live.audio_released / 2 ** 20, 1),
                           "rss_mb_peak": during["rss_mb_peak"], "fresh_during": during["fresh"],
                           "after": settled(service, f"{part[0]}z")}
    return {
        "benchmark": "serve-large-speech", "messages": n, "words_each": 10_000,
        "characters_each": [len(t) for t in texts], "load_average": [round(x, 2) for x in os.getloadavg()],
        "before": before, **parts,
        "rss_mb_above_baseline_after": round(parts["raised_limits"]["after"]["rss_mb"] - before["rss_mb"], 1),
        "targets": {"rss_above_baseline_after_mb": 100},
        "holds": {"rss_above_baseline_after_mb": all(
            part["after"]["rss_mb"] - before["rss_mb"] <= 100 for part in parts.values())},
    }


def slow_reader_clients(url: str, n: int, commands, out) -> None:
    """In a process of its own (the server's interpreter and RSS are then the server's alone): ``n`` clients on
    bare sockets that subscribe to the poses and read nothing; told ``k`` on ``commands``, close the ``k``
    oldest (those the server closed) and open ``k`` new ones; told None, close them all. Puts "ready" on
    ``out`` once the first ``n`` have subscribed, and the count of those opened when it stops."""
    import collections
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    from rawws import RawClient

    clients: collections.deque = collections.deque()
    opened = 0

    def add() -> None:
        nonlocal opened
        client = RawClient(url)
        client.send(json.dumps({"subscribe": "poses"}))
        clients.append(client)
        opened += 1

    for _ in range(n):
        add()
    out.put("ready")
    while (k := commands.get()) is not None:
        for _ in range(k):
            clients.popleft().close()
            add()
    for client in clients:
        client.close()
    out.put(opened)


def slow_readers(seconds: float, n: int) -> dict:
    import multiprocessing

    with Background(Service(port=0, audio="none", fps=30.0, tts=EspeakBackend())) as service:
        live, server = service.service.live, service.service.server
        fresh_client(service.url, live, "warm")
        time.sleep(1.0)
        before = settled(service, "a")
        context = multiprocessing.get_context("spawn")
        commands, out = context.Queue(), context.Queue()
        readers = context.Process(target=slow_reader_clients, args=(service.url, n, commands, out))
        readers.start()
        assert out.get(timeout=60) == "ready"
        started = time.monotonic()
        subscribed = [0.0] * n  # when each slow reader there subscribed, oldest first
        samples, fresh, closes, lived = [], [], [], []
        k = 0
        while time.monotonic() - started < seconds:
            samples.append((round(time.monotonic() - started, 1), round(rss_mb(), 1)))
            closed = server.counters["closed_not_reading"] - len(closes)
            if closed > 0:  # the server closes them in the order they stopped: the oldest
                now = time.monotonic() - started
                for _ in range(closed):
                    closes.append(round(now, 1))
                    lived.append(now - subscribed.pop(0))
                    subscribed.append(now)
                commands.put(closed)  # N slow readers there all the time
            if k % 10 == 5:
                fresh.append({"at_s": samples[-1][0], **fresh_client(service.url, live, f"d{k}")})
            k += 1
            time.sleep(max(0.0, started + k - time.monotonic()))
        commands.put(None)
        opened = out.get(timeout=60)
        readers.join(30)
        counters = dict(server.counters)
        time.sleep(3.0)
        after = settled(service, "z")
    during = fresh_summary(fresh)
    peak = max(r for _, r in samples)
    ratio = latency_ratio(during, before["fresh"])
    return {
        "benchmark": "serve-slow-readers", "slow_readers": n, "seconds": seconds,
        "load_average": [round(x, 2) for x in os.getloadavg()],
        "rss_mb": {"before": before["rss_mb"], "peak_during": peak, "end_of_during": samples[-1][1],
                   "after": after["rss_mb"]},
        "rss_samples": samples[::10],
        "fresh_client": {"before": before["fresh"], "during": during, "after": after["fresh"]},
        "latency_ratio_during": ratio, "latency_ratio_after": latency_ratio(after["fresh"], before["fresh"]),
        "slow_readers_opened": opened, "slow_readers_closed": len(closes), "slow_readers_closed_at_s": closes[:2 * n],
        "slow_reader_closed_after_s": {"median": median(lived), "max": round(max(lived), 1) if lived else None},
        "counters": counters,
        "targets": {"rss_above_baseline_mb": 50, "fresh_latency_ratio": 1.5},
        # (RSS: its peak during and what it is after; latency: the median during over the median before, and no
        # fresh client timed out)
        "holds": {"rss_above_baseline_mb": max(peak, after["rss_mb"]) - before["rss_mb"] <= 50,
                  "fresh_latency_ratio": ratio is not None and ratio <= 1.5 and not during["timed_out"]},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description="agentsim serve under a load of blocks")
    parser.add_argument("seconds", nargs="?", type=float, default=30.0)
    parser.add_argument("rate", nargs="?", type=float, default=20.0, help="blocks per second")
    parser.add_argument("--audio", default="none", help="output device for the speech (none)")
    parser.add_argument("--fps", type=float, default=0.0, help="poses per second for a subscribed viewer (0)")
    parser.add_argument("--duration", type=float, metavar="SECONDS", help="SECONDS, as an option")
    parser.add_argument("--slow-readers", type=int, default=0, metavar="N",
                        help="instead: N clients that subscribe to the poses and read nothing for SECONDS")
    parser.add_argument("--churn", type=int, default=0, metavar="N",
                        help="instead: N clients that connect, send a block and leave (for at most SECONDS)")
    parser.add_argument("--large-speech", type=int, default=0, metavar="N",
                        help="instead: N messages of a 10,000-word speech each")
    args = parser.parse_args()
    if args.duration is not None:
        args.seconds = args.duration
    if args.churn:
        print(json.dumps(churn(args.seconds, args.churn), indent=2))
        return
    if args.large_speech:
        print(json.dumps(large_speech(args.large_speech), indent=2))
        return
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
            "holds": {"lateness_spread_ms": bool(lateness.size) and float(np.ptp(lateness)) <= 20,
                      "interrupt_latency_ms": bool(latency.size) and float(latency.max()) <= 100},
            "poses": service.service.poses.cost() if service.service.poses is not None else None,
            "sound": None if service.service.sound is None else {
                "underruns": service.service.sound.underruns, "errors": service.service.sound.errors,
                "late_sounds": len(service.service.sound.late)},
        }
        print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
