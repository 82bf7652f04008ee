"""Drive a running `agentsim serve`: send a block, interrupt it while it speaks, print the feedback.

    agentsim serve --audio none &        # or with sound: agentsim serve
    python examples/live/client.py [ws://127.0.0.1:8765/]
"""

import json
import sys
import time

from websockets.sync.client import connect

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0" xmlns:bmla="http://www.asap-project.org/bmla"'
TALK = f"""<bml {NS} id="talk">
  <speech id="s1"><text>Let me tell you about the <sync id="w1"/>lighthouse on the hill,
    and the keeper who kept its <sync id="w2"/>lamp burning all through the longest storm.</text></speech>
  <gesture id="g1" lexeme="BEAT" stroke="s1:w1"/>
  <gesture id="g2" lexeme="BEAT" stroke="s1:w2"/>
</bml>"""
BARGE_IN = f"""<bml {NS} id="reply">
  <bmla:interrupt id="stop" target="talk"/>
  <speech id="s2" start="stop:start"><text>Oh, sorry. Go ahead.</text></speech>
</bml>"""


def show(item: dict) -> None:
    when = item.get("globalTime", 0.0)
    extra = item.get("description", "") if item["type"] == "warningFeedback" else ""
    print(f"{when:8.3f}  {item['type']:<20} {item['id']} {extra}")


def connect_when_up(url: str, wait: float = 15.0):
    """Connect to ``url``; a server just started in the background may still be starting: try again for up to
    ``wait`` seconds."""
    deadline = time.monotonic() + wait
    while True:
        try:
            return connect(url)
        except OSError as exc:
            if time.monotonic() > deadline:
                raise SystemExit(f"client: no agentsim serve at {url} ({exc}); start one with: agentsim serve") from None
            time.sleep(0.2)


def main(url: str) -> None:
    with connect_when_up(url) as ws:
        ws.send(TALK)
        sent_interrupt = None
        started = time.monotonic()
        while True:
            try:
                item = json.loads(ws.recv(timeout=0.1))
            except TimeoutError:
                item = None
            if item is not None and item["type"] != "predictionFeedback":
                show(item)
                if item["id"] == "reply:end":
                    return
            if sent_interrupt is None and time.monotonic() - started > 2.0:  # barge in after two seconds
                sent_interrupt = time.monotonic()
                ws.send(BARGE_IN)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "ws://127.0.0.1:8765/")
