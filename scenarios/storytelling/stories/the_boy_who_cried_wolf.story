# The Boy Who Cried Wolf: Aesop's fable, retold in new words for agentsim's virtual storyteller, with the
# emotions that its camera, light and music show ([emotion:TYPE,INTENSITY] until the next emotion tag or the
# paragraph's end). The fable is in the public domain; this retelling and its annotation are released into the
# public domain as well (CC0 1.0).
@title The Boy Who Cried Wolf
@author Aesop, retold for agentsim
@license Public domain (CC0 1.0)
@scene hill 1.2 2.2 2.8
@scene village -1.3 0.9 2.8
@scene sheep 0.8 0.6 2.2

[gaze:audience]There was [beat]once a [beat]shepherd boy who [emotion:neutral,1]watched the [point:sheep]sheep of his
[point:village]village on a [point:hill]hill above it. The [beat]days were [beat]long, and [emotion:distress,3]nothing
ever [beat]happened, and he was [shake]bored.

[emotion:joy,3.5][face:smile]One [beat]morning he had an [brows]idea. He [beat]ran down the hill and [beat:both]shouted,
"[beat]Wolf! [beat]Wolf! A wolf is [point:sheep]after the sheep!" The [point:village]people [beat]dropped their
[beat]work and [beat]came running up the hill. There was no [shake]wolf. The boy [beat]laughed and [beat]laughed
to [beat]see their [beat]faces.

[emotion:reproach,4][face:frown]"Do [beat]not cry wolf when there is [shake]no wolf," they [beat]told him, and they
[beat]went back down the [point:village]hill. [emotion:pride,2]But the boy [beat]only [nod]smiled.

[emotion:joy,5]A week [beat]later he [beat]did it [beat]again. "[beat:both]Wolf! [beat]Wolf!" And [beat]again the
people came [beat]running, and [beat]again there was [shake]no wolf, and [beat]again the boy [beat]laughed.
[emotion:anger,6]The people were [beat]angry now. They [icon:chop]said [beat]nothing, and [beat]went home.

[emotion:fear,6.5][gaze:hill][face:widen_eyes]Then, one [beat]evening, a [beat]real wolf came [beat]out of the
[point:hill]trees. The boy [beat]jumped up and [beat:both]cried, "[beat]Wolf! [beat]Wolf! [beat]Please, [beat]help!"
But in the [point:village]village nobody [shake]moved. "He is [beat]playing his [beat]trick again," they said.

[emotion:distress,7][gaze:audience]The wolf [beat]scattered the [point:sheep]flock, and the boy could do
[shake]nothing but [beat]watch. [emotion:neutral,1]And so the [beat]fable [beat]ends: [brows]nobody
[beat]believes a [icon:chop]liar, [beat]even when he [nod]tells the truth.
