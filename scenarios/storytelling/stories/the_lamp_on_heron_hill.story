# The Lamp on Heron Hill: an original story written for agentsim's virtual storyteller.
# The story text and its annotation are released into the public domain (CC0 1.0): anyone may copy,
# change and tell it, for any purpose, without asking.
#
# Annotation: a tag in square brackets stands in front of the word whose stressed syllable carries the
# gesture's stroke (see scenarios/storytelling/markup.py). The teller faces the audience; the places of
# the story lie around it (x: to the teller's left, y: up, z: ahead, in metres).
@title The Lamp on Heron Hill
@author written for agentsim
@license Public domain (CC0 1.0)
@scene hill 1.3 2.1 3.0
@scene lamp 1.0 2.5 2.6
@scene harbour -1.2 0.9 2.5
@scene sea 0.0 1.3 6.0
@scene boats -0.5 1.0 5.0
@scene rocks 2.2 0.9 4.5
@scene village -1.8 1.3 2.2
@scene door 0.9 1.2 1.3
@scene window -0.7 1.7 1.4
@scene sky 0.2 3.2 2.0
@scene path 0.8 0.7 1.8
@scene chair 0.4 0.8 1.0

[gaze:audience]Once upon a [beat]time, in a [icon:point_down]small grey [point:village]village at the [beat]edge of
the [point:sea]sea, there [beat]lived a [beat]girl called [brows]Nell and her [beat]grandfather, [beat]Tobias. Their
[beat]cottage stood at the [icon:point_down]very [beat]bottom of [gaze:hill]Heron [point:hill]Hill, and at the
[beat]very [point:lamp]top of the hill stood a [beat:both]tall iron [beat]lamp.

[gaze:audience]Every [beat]evening, when the [beat]sun slipped [icon:point_down]down behind the [point:sea]water, old
[beat]Tobias took his [beat]stick and his [beat]can of [beat]oil and [beat]climbed the [point:path]long path to the
[point:lamp]top. [nod]There he [beat]lit the lamp. It [beat]burned all [beat]night, a [icon:offer]small gold
[point:sky]star above the [beat]dark, and the [beat]fishermen out on the [point:sea]sea would [beat]see it and
[beat]know the way [beat]home. For [beat:both]forty [beat]years he had [shake]never [icon:chop]missed a
[beat]single night. [shake]Not in [beat]rain, [shake]not in [beat]snow, [brows]not even on the [beat]night
Nell was [beat]born.

[gaze:window]"Why do you [beat]climb every night, [brows]Grandfather?" Nell [beat]asked him once. "The
[point:boats]boats [beat]know the way. They have [beat]sailed it a [beat:both]thousand times."

[gaze:audience][face:smile]Tobias [beat]laughed, a [beat]low laugh like a [beat]cart on a [beat]stony road.
"In the [beat]daylight, they [nod]do," he said. "But the [point:sea]sea at [beat]night is a [brows]different
sea. It has [shake]no [beat]roads and [icon:chop]no signs. A [beat]man can be a [beat:both]mile from his own
[point:door]door and [shake]not [beat]know it. The [point:lamp]lamp is the [icon:offer]only thing that
[beat]tells him where [beat]home is."

[gaze:audience]Nell [beat]thought about that for a [beat]long time. She thought about it while she
[beat]mended nets, and while she [beat]fed the hens, and while she [icon:point_down]lay in bed
[beat]listening to the [point:sea]waves. A [beat:both]mile from his own [beat]door, and [shake]not know it. It
[beat]seemed to her the [brows]saddest [beat]thing in the [icon:offer:both]world.

[gaze:audience][face:frown]Then came the [beat]winter of the [beat:both]great [beat]storm.

It [beat]began with a [brows]strange, [beat]still morning. The [point:sea]sea was [icon:chop]flat as a
[beat]plate, and the [beat]gulls did [shake]not fly. The [beat]old women of the [point:village]village looked at
the [point:sky]sky and [shake]shook their heads. By [beat]noon the [beat]wind had come up from the
[point:left]north, and by the [beat]middle of the afternoon it was [beat]howling around the
[beat]chimneys like a [brows]wolf at a [beat]gate.

[gaze:chair]That same [beat]afternoon, Tobias [icon:point_down]fell [beat]ill. He had been [beat]coughing for
[beat]days, but [beat]now he could [shake]not stand. His [beat]face was [beat]grey and his [beat]hands were
[beat]cold, and when he [beat]tried to get [beat]up from his [point:chair]chair, his [beat]legs would
[shake]not [beat]hold him.

[gaze:audience]"The [point:lamp]lamp," he [beat]whispered. "[brows]Nell, the [beat]lamp. The [beat]Harper
brothers are [beat]still out. And [beat]young Sam [beat]Fletcher. [beat:both]Three boats, Nell. Three
[beat]boats out on the [point:sea]water."

[gaze:window]Nell [beat]looked out of the [point:window]window. [icon:point_down]Down in the
[point:harbour]harbour, the [beat]empty moorings [beat]rocked and [beat]jumped. [beat]Beyond them, the
[point:sea]sea had turned [beat]white with [beat]foam. [point:up]Up on the hill, the [point:lamp]lamp stood
[beat]cold and [beat]dark against the [point:sky]clouds.

[gaze:audience][nod]"I will [icon:offer]go," she said.

"You are [beat]ten years [beat]old," said [beat]Tobias.

[face:smile]"I am [beat]ten and a [brows]half," said [beat]Nell. "And I [beat]know the [point:path]path as
[beat]well as you do. I have [beat]watched you [beat]climb it every [beat]night of my [icon:offer]life."

Her [beat]grandfather looked at her for a [beat]long moment. Then he [nod]nodded, [beat]very
[beat]slowly. "[beat]Take the oil," he said. "[beat]Take the [beat]matches, and keep them [icon:chop]dry
inside your [beat]coat. And when you [beat]reach the [point:lamp]top, [beat]hold on to the [beat]iron post
and do [shake]not let go. The [beat]wind up there will [beat]try to [beat]carry you off like a
[brows]leaf."

[gaze:door]So Nell put on her [beat]grandfather's [beat:both]big coat, which came [icon:point_down]down to her
[beat]ankles, and she [beat]tied a scarf around her [beat]head, and she took the [beat]can of oil and the
[beat]box of matches, and she [point:door]opened the door.

[face:surprise]The wind [icon:chop]hit her like a [beat:both]wall. It [beat]pushed her back into the
[beat]house, and she had to [beat]lean on the [point:door]door with [beat]all her weight to [beat]close it
behind her. Then she [beat]turned and [point:path]began to climb.

[gaze:hill]The [beat]path up Heron Hill was [beat]narrow and [point:hill]steep, and in the [beat]storm it was
[brows]worse than she had [beat]ever imagined. [beat]Rain came [point:right]sideways, [beat]stinging her
face like [beat]sand. The [icon:point_down]mud sucked at her [beat]boots. [beat:both]Twice she [beat]slipped
and fell to her [beat]knees, and [beat:both]twice she got [beat]up again, [beat]holding the can of oil
against her [beat]chest as if it were a [brows]baby. [icon:point_down]Below her, the [beat]lights of the
[point:village]village grew [beat]small. [point:up]Above her, there was [shake]nothing but [beat]wind and
[beat]darkness and the [beat]black shape of the [point:hill]hill.

[gaze:sea][beat]Halfway up, she [beat]stopped to [beat]breathe, and she looked [beat]back at the
[point:sea]sea. For [beat]one moment the [point:sky]clouds broke [icon:offer:both]open, and in the [beat]grey
light she [brows]saw them: [beat:both]three tiny [point:boats]boats, far [beat]out, [beat]tossed up and down on
the [beat]waves like [beat]corks in a [beat]bucket. They were [shake]not coming [beat]home. They were going the
[icon:chop]wrong way, [point:left]north, towards the [point:rocks]rocks at [beat]Gannet Point.

[gaze:audience]Nell did [shake]not [icon:chop]stop again.

[gaze:lamp]When she [beat]reached the [point:lamp]top, the [beat]wind was so [beat:both]strong she could
[beat]hardly stand. She [beat]grabbed the [beat]iron post with [beat]one arm, just as her
[beat]grandfather had told her, and with the [beat]other she [beat]pulled open the [beat]little glass
door of the [point:lamp]lamp. She [beat]poured in the oil. Her [beat]hands were [beat]shaking with
[beat]cold. She [beat]took out the box of matches and [beat]struck the [beat]first one.

[gaze:audience]The [beat]wind [icon:chop]blew it out at [brows]once.

She struck the [beat]second. The wind [icon:chop]blew it out.

She struck a [beat]third, a [beat]fourth, a [beat]fifth. [beat:both]Every one went [beat]out before it could
[beat]touch the wick. Nell [beat]counted what was [beat]left in the box. [beat:both]Two matches.
[face:widen_eyes][brows]Only [beat]two.

[gaze:down]She [icon:point_down]sat down in the [beat]mud at the [beat]foot of the lamp, and for a
[beat]moment she [beat]wanted to [beat]cry. [gaze:audience]Then she [beat]remembered what her grandfather had
[beat]said. A [beat:both]mile from his own [point:door]door, and [shake]not know it.

So she [beat]stood up again. She [beat]opened her [beat:both]big coat and [beat]wrapped it around the
[point:lamp]lamp like a [beat]tent, so that the lamp and her [beat]own face were [icon:point_down]inside it
together, and the [beat]wind was [point:right]outside. In that [beat]small dark space, out of the
[beat]wind, she [beat]struck the second to [beat]last match. It [brows]flared, and [beat]fizzed, and
[icon:chop]caught. [beat]Very [beat]carefully, she [beat]held it to the [beat]wick.

[gaze:lamp]The [beat]wick took the [beat]flame. The flame [beat]grew. And the [point:lamp]lamp on Heron
Hill [face:smile]began to [brows]shine.

Nell [beat]closed the little glass door and [beat]stepped back, and the light [icon:offer:both]poured
out over the [point:hill]hill and [icon:point_down]down across the [point:sea]water, [beat]gold and
[beat]steady, [beat]brighter than she had [beat]ever [beat]seen it.

[gaze:boats]Out on the [point:sea]sea, Sam [beat]Fletcher was the [beat]first to see it. He had been
[beat]lost for an [beat]hour, [beat]turning this way and [beat]that, with [shake]no idea which way was
[beat]land. Then, through the [beat]rain, he [brows]saw a [beat]small gold [point:lamp]star low in the
[beat]sky, [icon:chop]exactly where the lamp should [beat]be. He [beat]shouted to the [beat]Harper brothers,
and they [beat]turned their boats [beat:both]together, [point:rocks]away from the rocks at Gannet Point,
and [beat]followed the [point:lamp]light [beat]home.

[gaze:audience]Nell [beat]stayed by the lamp [beat:both]all night. She [beat]held on to the iron post, and
she kept the [beat]glass [beat]clean of rain with her [beat]sleeve, and she sang [beat:both]every song
she [beat]knew to keep herself [beat]awake. [face:smile]Sometimes she sang them [brows]twice.

[gaze:sky]At [beat]dawn the [beat]storm blew itself [icon:chop]out. The [point:sky]clouds broke, and the
[beat]sun came up [beat]pink and [beat]gold over a [point:sea]sea that was [icon:offer:both]calm again.
[gaze:harbour]Nell looked [icon:point_down]down, and [beat]there, tied up [beat]safe in the
[point:harbour]harbour, were [beat:both]three small [beat]boats.

[gaze:path]Then she saw [brows]something else. A [beat:both]long line of [beat]people was coming [point:path]up the
path: the [beat]Harper brothers, and Sam [beat]Fletcher, and their [beat]wives and their [beat]children, and
[beat:both]half the [point:village]village behind them. And at the [beat]front, leaning on [beat]Sam's arm,
[beat]wrapped in three [beat]blankets, was her [brows]grandfather.

[gaze:audience][shake]Nobody said [beat]anything for a while. Then the [beat]oldest Harper brother
[beat]took off his [beat]hat. "We [beat]thought it was [beat]Tobias who lit the lamp," he said. "We
[beat]thought, the old [beat]man has [nod]done it again."

[face:smile]"It was the [beat]old man's [point:lamp]lamp," said Tobias, and his [beat]eyes were
[beat]bright. "But it was the [icon:offer]young one who [nod]lit it."

[gaze:hill]From that night [beat]on, Nell and her [beat]grandfather [beat]climbed the [point:hill]hill
[beat:both]together, every [beat]evening, in [beat:both]every kind of [beat]weather. And when, [beat]many years
later, Tobias could [shake]not climb at [beat]all, Nell [beat]climbed [icon:point_down]alone, and [beat]lit the
[point:lamp]lamp, and [beat]looked out across the [beat]dark water at the [point:boats]boats coming
[beat]home.

[gaze:audience]People [beat]say the [point:lamp]lamp still [beat]burns on Heron Hill. And [brows]if you are ever
[beat]lost at [point:sea]sea on a [beat]stormy night, [beat]look for a [icon:offer]small gold star, [beat]low
over the [point:hill]land. That will be [beat]Nell, or [beat]someone very [nod]like her, [beat]showing you the
[beat]way [point:audience]home.
