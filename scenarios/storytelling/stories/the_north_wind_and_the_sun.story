# The North Wind and the Sun: Aesop's fable, retold in new words for agentsim's virtual storyteller.
# The fable is in the public domain; this retelling and its annotation are released into the public
# domain as well (CC0 1.0).
@title The North Wind and the Sun
@author Aesop, retold for agentsim
@license Public domain (CC0 1.0)
@scene sky 0.3 3.0 2.5
@scene road -1.2 0.8 2.5
@scene traveller -0.6 1.2 3.0
@scene river 1.4 0.6 2.8

[gaze:audience]Long [beat]ago, the [point:left]North Wind and the [point:sky]Sun had a [brows]quarrel. Each of them
[beat]said that [icon:chop]he was the [beat:both]stronger.

[gaze:road]Just then a [beat]traveller came [point:road]walking along the road, [beat]wrapped in a [beat]thick
[icon:offer]cloak. "[nod]Let us [beat]settle it," said the [beat]Sun. "[beat]Whoever can take the [beat]cloak off
that [point:traveller]man is the [beat]stronger of us."

[gaze:left][face:frown]The [beat]North Wind went [beat]first. He [beat]blew a [beat:both]cold, [beat]hard
blast, and then a [beat]harder one, and then the [beat:both]hardest he could. But the [beat]more he
[beat]blew, the [beat]tighter the traveller [icon:point_down]held his cloak, [beat]until at [beat]last the
Wind [shake]gave up.

[gaze:sky][face:smile]Then the [beat]Sun came [point:sky]out. He [beat]shone, [beat]warm and [beat]gentle, and
the [beat]traveller [beat]loosened his cloak. The Sun shone [beat]warmer still, and the man [beat]took the
cloak [icon:offer]off. At [beat]last, [beat]hot and [beat]tired, he [beat]threw off [beat]everything he
wore and [beat]jumped into a [point:river]river to [beat]cool down.

[gaze:audience][nod]So the [beat]Sun [beat]won. [brows]Kindness [beat]often does what [icon:chop]force
[shake]cannot.
