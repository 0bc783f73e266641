"""The README's command examples still print what it shows (``docs/readme_examples.py``), every one of them."""

from __future__ import annotations

from docs.readme_examples import README, check, parse, same_line


def test_a_drifted_example_is_caught_and_updated(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("text\n<!-- example -->\n```\n$ echo one; echo two  # a comment\none\nthree\n```\n")
    (diff,) = check(readme)
    assert "-three" in diff and "+two" in diff
    check(readme, update=True)
    assert check(readme) == [] and "one\ntwo\n```" in readme.read_text()


def test_numbers_match_within_the_solvers_tolerance_text_and_integers_exactly():
    assert same_line('  "final_error_m": 0.80884,', '  "final_error_m": 0.8087587,')  # another CPU's kernels
    assert same_line("distance -0.4472418", "distance -0.4472415")
    assert not same_line('  "final_error_m": 0.80884,', '  "final_error_m": 0.8121,')  # 0.4%: a change
    assert not same_line("79 steps, 49.8 m", "80 steps, 49.8 m")  # integers exactly
    assert not same_line("79 steps, 49.8 m", "79 steps, 50.0 m")  # two units of the last digit shown: a change
    assert same_line("79 steps, 49.8 m", "79 steps, 49.9 m")  # one unit: the rounding of a value that barely moved
    assert same_line("last change 0.0208 m", "last change 0.0209 m")
    assert not same_line("graph fusion", "batch fusion")


def test_readme_examples_print_what_the_readme_shows():
    examples = parse(README.read_text(encoding="utf-8").splitlines())
    assert len(examples) >= 3
    diffs = check()
    assert not diffs, "\n\n".join(diffs) + "\n\nrun: python docs/readme_examples.py --update"
