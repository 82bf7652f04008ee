"""General MIDI instruments: program names and aliases, the percussion channel and kit, and the band's parts."""

from __future__ import annotations

__all__ = [
    "DRUM_CHANNEL",
    "DRUM_KIT",
    "KICK",
    "SNARE",
    "HIHAT",
    "PARTS",
    "PART_PROGRAMS",
    "GM_PROGRAMS",
    "INSTRUMENT_ALIASES",
    "DRUM_NAMES",
    "gm_program",
    "program_name",
    "default_part",
]

DRUM_CHANNEL = 9
"""General MIDI percussion channel (channel 10, counting from one)."""

DRUM_KIT = -1
"""Program number that stands for the General MIDI percussion kit (played on :data:`DRUM_CHANNEL`)."""

#: Percussion keys (General MIDI) of the bass drum, the acoustic snare and the closed hi-hat.
KICK, SNARE, HIHAT = 36, 38, 42

#: Lines of the generated score (see :func:`agentsim.music.score.build_score`).
PARTS = ("drums", "bass", "piano", "strings")

#: MIDI channel and General MIDI program of each melodic part.
PART_PROGRAMS = {"piano": (0, 0), "bass": (1, 33), "strings": (2, 49)}

#: General MIDI program names (program number = index), lower case with underscores.
GM_PROGRAMS: tuple[str, ...] = (
    "acoustic_grand_piano", "bright_acoustic_piano", "electric_grand_piano", "honky_tonk_piano",
    "electric_piano_1", "electric_piano_2", "harpsichord", "clavinet",
    "celesta", "glockenspiel", "music_box", "vibraphone", "marimba", "xylophone", "tubular_bells", "dulcimer",
    "drawbar_organ", "percussive_organ", "rock_organ", "church_organ", "reed_organ", "accordion", "harmonica",
    "tango_accordion",
    "acoustic_guitar_nylon", "acoustic_guitar_steel", "electric_guitar_jazz", "electric_guitar_clean",
    "electric_guitar_muted", "overdriven_guitar", "distortion_guitar", "guitar_harmonics",
    "acoustic_bass", "electric_bass_finger", "electric_bass_pick", "fretless_bass", "slap_bass_1", "slap_bass_2",
    "synth_bass_1", "synth_bass_2",
    "violin", "viola", "cello", "contrabass", "tremolo_strings", "pizzicato_strings", "orchestral_harp", "timpani",
    "string_ensemble_1", "string_ensemble_2", "synth_strings_1", "synth_strings_2", "choir_aahs", "voice_oohs",
    "synth_voice", "orchestra_hit",
    "trumpet", "trombone", "tuba", "muted_trumpet", "french_horn", "brass_section", "synth_brass_1", "synth_brass_2",
    "soprano_sax", "alto_sax", "tenor_sax", "baritone_sax", "oboe", "english_horn", "bassoon", "clarinet",
    "piccolo", "flute", "recorder", "pan_flute", "blown_bottle", "shakuhachi", "whistle", "ocarina",
    "lead_1_square", "lead_2_sawtooth", "lead_3_calliope", "lead_4_chiff", "lead_5_charang", "lead_6_voice",
    "lead_7_fifths", "lead_8_bass_lead",
    "pad_1_new_age", "pad_2_warm", "pad_3_polysynth", "pad_4_choir", "pad_5_bowed", "pad_6_metallic", "pad_7_halo",
    "pad_8_sweep",
    "fx_1_rain", "fx_2_soundtrack", "fx_3_crystal", "fx_4_atmosphere", "fx_5_brightness", "fx_6_goblins",
    "fx_7_echoes", "fx_8_sci_fi",
    "sitar", "banjo", "shamisen", "koto", "kalimba", "bagpipe", "fiddle", "shanai",
    "tinkle_bell", "agogo", "steel_drums", "woodblock", "taiko_drum", "melodic_tom", "synth_drum", "reverse_cymbal",
    "guitar_fret_noise", "breath_noise", "seashore", "bird_tweet", "telephone_ring", "helicopter", "applause",
    "gunshot",
)
#: Short names for common instruments.
INSTRUMENT_ALIASES = {"piano": 0, "bass": 33, "finger_bass": 33, "strings": 49, "slow_strings": 49,
                      "electric_piano": 4, "organ": 16, "guitar": 24}
#: Names of the General MIDI percussion kit (channel 10).
DRUM_NAMES = ("drums", "drum_kit", "standard_kit", "percussion")


def gm_program(name: "str | int") -> int:
    """The General MIDI program of an instrument name or number.

    Parameters
    ----------
    name : str or int
        A General MIDI name as in :data:`GM_PROGRAMS` (case, spaces and hyphens do not matter), a
        short name of :data:`INSTRUMENT_ALIASES`, one of :data:`DRUM_NAMES`, or a program number.

    Returns
    -------
    int
        The program, 0..127, or :data:`DRUM_KIT` for the percussion kit.

    Raises
    ------
    ValueError
        For a number outside 0..127 or an unknown name; the message suggests similar names.
    """
    if isinstance(name, int) and not isinstance(name, bool):
        if 0 <= name <= 127:
            return name
        raise ValueError(f"General MIDI program {name} is outside 0..127")
    key = str(name).strip().lower().replace(" ", "_").replace("-", "_")
    if key in DRUM_NAMES:
        return DRUM_KIT
    if key in INSTRUMENT_ALIASES:
        return INSTRUMENT_ALIASES[key]
    if key in GM_PROGRAMS:
        return GM_PROGRAMS.index(key)
    close = [n for n in GM_PROGRAMS + tuple(INSTRUMENT_ALIASES) if key[:4] and key[:4] in n][:6]
    hint = f"; did you mean {', '.join(close)}?" if close else ""
    raise ValueError(f"unknown instrument {name!r}: use a General MIDI name (e.g. acoustic_grand_piano, "
                     f"electric_bass_finger, string_ensemble_2), a program number 0..127 or drums{hint}")


def program_name(program: int) -> str:
    """The General MIDI name of a program (0..127), or ``"drums"`` for the percussion kit (a negative program)."""
    return "drums" if program < 0 else GM_PROGRAMS[program]


def default_part(program: int) -> str:
    """The part of the generated score an instrument plays unless told otherwise.

    The percussion kit plays the drums, the basses (programs 32..39) the bass line, programs 40..55
    (strings, ensembles, voices) and the pads (88..95) the sustained chords of the strings, and
    everything else the piano's chords.
    """
    if program < 0:
        return "drums"
    if 32 <= program <= 39:
        return "bass"
    if 40 <= program <= 55 or 88 <= program <= 95:
        return "strings"
    return "piano"
