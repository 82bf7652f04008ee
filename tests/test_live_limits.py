"""How much speech a block sent to ``agentsim serve`` may ask for: a block past a limit (characters or seconds,
per speech or per block) is refused whole with one warning to its sender, before it costs anything; the audio
synthesised for a block is weighed in bytes and released when the block ends. With a real WebSocket client and
espeak-ng (the backend that makes sound)."""

from __future__ import annotations


import pytest
from websockets.sync.client import connect

from agentsim.live.limits import CHARACTERS_PER_SECOND, Limits
from agentsim.live.service import Background, Service
from speech_timing.espeak import EspeakBackend
from tests.helpers import receive

NS = 'xmlns="http://www.bml-initiative.org/bml/bml-1.0" xmlns:bmla="http://www.asap-project.org/bmla"'
SENTENCE = "The keeper of the lighthouse walked up the hill. "  # 49 characters


@pytest.fixture(scope="module")
def service():
    with Background(Service(port=0, audio="none", fps=0, tts=EspeakBackend())) as running:
        yield running


def speeches(block_id: str, *lengths: int) -> str:
    """A block with one speech of about each length (characters), made of :data:`SENTENCE`."""
    body = "".join(f'<speech id="s{i}"><text>{(SENTENCE * (n // len(SENTENCE) + 1))[:n].strip()}</text></speech>'
                   for i, n in enumerate(lengths))
    return f'<bml {NS} id="{block_id}">{body}</bml>'


def status(ws) -> dict:
    ws.send('{"status": true}')
    return receive(ws, lambda m: m.get("type") == "status")[-1][1]


def refused(service, ws, limits: Limits, document: str, block_id: str) -> list[dict]:
    """What the sender hears of a document under ``limits``: up to a small block sent after it has ended."""
    service.service.intake.limits = limits
    ws.send(document)
    ws.send(f'<bml {NS} id="after_{block_id}"><head id="h" lexeme="NOD"/></bml>')
    got = [m for _, m in receive(ws, lambda m: m["id"] == f"after_{block_id}:end", timeout=30)]
    return [m for m in got if str(m["id"]).split(":")[0] == block_id]


@pytest.mark.parametrize("limits, lengths, says", [
    (Limits(speech_characters=500), (600,), "speech s0 has 600 characters, more than the 500 a speech may have "
                                            "here (--max-speech-chars)"),
    (Limits(speech_seconds=10), (300,), f"speech s0 would last some {300 / CHARACTERS_PER_SECOND:,.0f} s, longer "
                                        "than the 10 s a speech may last here (--max-speech-seconds)"),
    (Limits(block_characters=500), (300, 300), "its speeches have 600 characters, more than the 500 a block may "
                                               "have here (--max-block-chars)"),
    (Limits(block_seconds=10), (100, 100), f"its speeches would last some {200 / CHARACTERS_PER_SECOND:,.0f} s, "
                                           "longer than the 10 s a block's speech may last here "
                                           "(--max-block-seconds)"),
])
def test_a_block_past_a_limit_is_refused_with_one_warning(service, limits, lengths, says):
    with connect(service.url) as ws:
        before = status(ws)["refused_long_blocks"]
        heard = refused(service, ws, limits, speeches("long", *lengths), "long")
        assert [m["type"] for m in heard] == ["warningFeedback"]  # nothing of it ran
        assert heard[0]["description"] == f"block refused: {says}"
        after = status(ws)
    assert after["refused_long_blocks"] == before + 1 and after["speech_audio_bytes"] == 0


def test_a_speech_the_estimate_lets_through_is_refused_on_its_audio(service):
    # letters spelled one by one: 4 characters of text, a second and a half of speech
    text = "QXZ " * 20
    assert len(text.strip()) / CHARACTERS_PER_SECOND < 5
    with connect(service.url) as ws:
        heard = refused(service, ws, Limits(speech_seconds=5),
                        f'<bml {NS} id="spelled"><speech id="s"><text>{text}</text></speech></bml>', "spelled")
        (warning,) = heard
        assert warning["description"].startswith("block refused: speech s lasts ")
        assert "longer than the 5 s a speech may last here (--max-speech-seconds)" in warning["description"]
        assert float(warning["description"].split("lasts ")[1].split(" s")[0]) > 5
        assert status(ws)["speech_audio_bytes"] == 0


def test_a_blocks_audio_is_weighed_and_released_when_it_ends(service):
    live = service.service.live
    service.service.intake.limits = Limits()
    with connect(service.url) as ws:
        released = status(ws)["speech_audio_released"]
        ws.send(speeches("talk", 2000))
        got = receive(ws, lambda m: m["id"] == "talk:s0:start", timeout=30)
        (prediction,) = [m for _, m in got if m["type"] == "predictionFeedback" and m["id"] == "talk"][:1]
        (speech,) = prediction["behaviours"]
        seconds = speech["globalEnd"] - speech["globalStart"]
        held = status(ws)["speech_audio_bytes"]
        # 16-bit samples at espeak-ng's 22,050 Hz: the speech's length, weighed
        assert held == pytest.approx(seconds * 22050 * 2, rel=0.01)
        (started,) = [s for s in live.realizer.speech._started if s[0].block_id == "talk"]
        assert started[1].audio is not None and started[1].audio.held_bytes == held
        ws.send(f'<bml {NS} id="stop"><bmla:interrupt id="i" target="talk"/></bml>')
        receive(ws, lambda m: m["id"] == "talk:end")
        after = status(ws)
    assert after["speech_audio_bytes"] == 0 and after["speech_audio_released"] == released + held
    assert started[1].audio is None  # let go where the realizer kept it


def test_limits_must_be_positive():
    from agentsim.errors import UsageError

    with pytest.raises(UsageError, match="--max-block-seconds must be a positive number"):
        Limits(block_seconds=0)
    with pytest.raises(UsageError, match="--max-speech-chars must be a positive number"):
        Limits(speech_characters=-1)


def test_a_client_sending_many_long_speeches_delays_another_by_one_at_most(service):
    """The reader takes each client's documents in turn: a block sent just after five long speeches of another
    client is read after the first of them, not after all five (each takes a while to synthesise)."""
    service.service.intake.limits = Limits()
    with connect(service.url) as greedy, connect(service.url) as other:
        for i in range(5):
            greedy.send(speeches(f"long{i}", 5000))
        other.send(f'<bml {NS} id="quick"><head id="h" lexeme="NOD"/></bml>')
        quick = receive(other, lambda m: m["id"] == "quick:start", timeout=60)[-1][1]["globalTime"]
        started = {}
        for _, m in receive(greedy, lambda m: m["id"] == "long4:start", timeout=60):
            if m["type"] == "blockProgress" and m["id"].endswith(":start"):
                started[m["id"].split(":")[0]] = m["globalTime"]
        for i in range(5):
            greedy.send(f'<bml {NS} id="stop{i}"><bmla:interrupt id="i" target="long{i}"/></bml>')
        receive(greedy, lambda m: m["id"] == "long4:end", timeout=30)
    assert started["long0"] <= quick < started["long1"], (quick, started)
