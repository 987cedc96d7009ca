"""File names from a user's words (:mod:`mitsuba_platonic.files.names`): readable in any script, never a path."""

import unicodedata

from mitsuba_platonic.files.names import readable_name, readable_stem


def test_letters_marks_and_digits_of_any_script_are_kept_in_composed_form():
    assert readable_name("ñandú 木の椅子 हिन्दी ٣") == "ñandú_木の椅子_हिन्दी_٣"
    assert readable_name(unicodedata.normalize("NFD", "Tür")) == "Tür"                  # macOS's decomposed ü


def test_everything_else_becomes_an_underscore_each_or_one_per_run():
    assert readable_name("a/b\\c d\u202ee\udcff.f") == "a_b_c_d_e__f"
    assert readable_name("a/b\\c", keep="\\") == "a_b\\c"
    assert readable_name("a / b", collapse=True) == "a_b" and readable_name("a__b", collapse=True) == "a__b"


def test_a_figure_stem_of_a_run_name_stays_readable():
    assert readable_stem("Stühle (platonic, step 2)", "run") == "Stühle_platonic_step_2"
    assert readable_stem("ñandú.v1", "run") == "ñandú.v1"
    assert readable_stem("/ () /", "row") == "row"
