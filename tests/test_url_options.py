"""Source URL options read by one module (rtseg.drivers.options): every scheme refuses a
bad value before opening anything, in one line naming the scheme and the option."""

import pytest

from rtseg.drivers import open_source
from rtseg.drivers.base import SourceError
from rtseg.drivers.options import flag_option, number_option


@pytest.mark.parametrize("url, message", [
    ("serial:///dev/null?rate=nan", "serial:// option rate='nan': must be finite"),
    ("serial:///dev/null?baud=10", "serial:// option baud=10: out of range 50..50000000"),
    ("serial:///dev/null?queue=2.5", "serial:// option queue='2.5': expected an integer"),
    ("serial:///dev/null?wait=maybe", "serial:// option wait='maybe': expected 1 or 0"),
    ("serial:///dev/null?speed=2", "serial:// unknown option(s) speed; known: backoff"),
    ("osc://127.0.0.1:0?rate=inf", "osc:// option rate='inf': must be finite"),
    ("rokoko://127.0.0.1:0?queue=0", "rokoko:// option queue=0: out of range 1..1000000"),
    ("mvn://127.0.0.1:0?character=x", "mvn:// option character='x': expected an integer"),
    ("serial:///dev/null?format=bin", "serial:// option format='bin': expected rtseg, text"),
    ("serial:///dev/null?suit=nosuch", "serial source: "),
    ("file:///nonexistent.bvh?timing=real", "file:// option timing='real': expected nominal"),
])
def test_a_bad_option_is_refused_in_one_line_before_anything_opens(url, message):
    with pytest.raises(SourceError) as err:
        open_source(url)
    assert str(err.value).startswith(message)
    assert "\n" not in str(err.value)


def test_flags_and_numbers_read_their_spellings_and_defaults():
    opts = {"a": "", "b": "off", "c": "Yes", "n": "", "m": "7"}
    assert [flag_option("x", opts, k) for k in "abc"] == [True, False, True]
    assert flag_option("x", opts, "absent", True) is True
    assert number_option("x", opts, "n", 3.0) == 3.0          # empty: the default
    assert number_option("x", opts, "m", None, int, {"m": (0, 10)}) == 7
    with pytest.raises(SourceError, match=r"x:// option m=7: out of range 8..9"):
        number_option("x", opts, "m", None, int, {"m": (8, 9)})


def test_an_unknown_suit_is_named_without_quotes_around_the_message():
    with pytest.raises(SourceError) as err:
        open_source("serial:///dev/null?suit=nosuch")
    assert "unknown suit 'nosuch'" in str(err.value) and '"' not in str(err.value)


@pytest.mark.parametrize("query", ["suit=", "suits=", "format="])
def test_an_empty_serial_text_option_is_its_default(query, tmp_path):
    # suit= was 'unknown suit', suits= read the working folder as a TOML file ('. is a
    # folder'), format= was refused: the device is now opened (and found missing)
    with pytest.raises(SourceError, match="cannot open serial device"):
        open_source(f"serial://{tmp_path}/absent?{query}")


def test_an_empty_replay_text_option_is_its_default(tmp_path):
    # space= and timing= were refused ("expected local or global", "timing must be ...")
    from rtseg.drivers.readers import write_take

    src = open_source("sim://synth?script=walk:2&rate=30&speed=0&space=")
    assert src.space == "local" and src.n_frames == 60
    path = write_take(tmp_path / "walk.npz", src.take)
    src = open_source(f"file://{path}?speed=0&space=&timing=")
    assert src.space == "local" and src.n_frames == 60 and not src._recorded
