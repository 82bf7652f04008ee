"""A count-in anticipator: ``count1`` ... ``countN`` every ``period`` seconds from ``start``, then ``cue``.

After ``delay`` seconds of simulated time it decides the cue comes ``shift`` seconds later: everything
tied to the cue is re-timed.
"""

import re

from anticipators import Anticipator


class CountIn(Anticipator):
    def __init__(self, anticipator_id="countin", beats=4, period=0.5, start=0.0, delay=None, shift=0.0):
        super().__init__(anticipator_id)
        self.beats, self.period, self.start = int(beats), float(period), float(start)
        self.delay, self.shift = delay, float(shift)

    def make_peg(self, sync_id):
        if sync_id == "cue":
            return self.start + self.beats * self.period
        match = re.fullmatch(r"count(\d+)", sync_id)
        if match and 1 <= int(match.group(1)) <= self.beats:
            return self.start + (int(match.group(1)) - 1) * self.period
        return False

    def run(self):
        if self.delay is None:
            return None
        return self._later()

    def _later(self):
        yield self.env.timeout(float(self.delay))
        cue = self.peg("cue")
        cue.set(cue.time + self.shift)
