"""Live service under load: a real WebSocket client sends 20 blocks a second for 30 s to ``agentsim serve``
(each a speech with a beat on a word and a nod, espeak-ng timing them), and every second one speech is
interrupted while it plays.

Prints JSON: the lateness of every timed feedback (arrival on the client minus the moment its
``globalTime`` stands for on the server's clock; p50, p95, max, and the spread max - min), the interrupt
latency (from sending a ``bmla:interrupt`` to the arrival of the interrupted speech's end; p50, p95, max),
how many blocks ran and how many the server refused. Targets: lateness spread within 20 ms, interrupt
latency within 100 ms.

    python benchmarks/bench_serve.py [SECONDS] [BLOCKS_PER_SECOND] [--audio DEVICE] [--fps N]

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

import numpy as np
from websockets.sync.client import connect

from agentsim.live.service import Background, Service
from speech_timing.espeak import EspeakBackend

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0" xmlns:bmla="http://www.asap-project.org/bmla"'


def block(i: int) -> str:
    return (f'<bml {NS} id="b{i}"><speech id="s"><text>Block {i} says <sync id="w"/>hello to you.</text></speech>'
            f'<gesture id="g" lexeme="BEAT" stroke="s:w"/><head id="h" lexeme="NOD" start="s:end"/></bml>')


def main() -> None:
    parser = argparse.ArgumentParser(description="agentsim serve under a load of blocks")
    parser.add_argument("seconds", nargs="?", type=float, default=30.0)
    parser.add_argument("rate", nargs="?", type=float, default=20.0, help="blocks per second")
    parser.add_argument("--audio", default="none", help="output device for the speech (none)")
    parser.add_argument("--fps", type=float, default=0.0, help="poses per second for a subscribed viewer (0)")
    args = parser.parse_args()
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
