"""The README's command examples still print what it shows (``docs/readme_examples.py``), every one of them."""

from __future__ import annotations

from docs.readme_examples import README, check, parse


def test_a_drifted_example_is_caught_and_updated(tmp_path):
    readme = tmp_path / "README.md"
    readme.write_text("text\n<!-- example -->\n```\n$ echo one; echo two  # a comment\none\nthree\n```\n")
    (diff,) = check(readme)
    assert "-three" in diff and "+two" in diff
    check(readme, update=True)
    assert check(readme) == [] and "one\ntwo\n```" in readme.read_text()


def test_readme_examples_print_what_the_readme_shows():
    examples = parse(README.read_text(encoding="utf-8").splitlines())
    assert len(examples) >= 3
    diffs = check()
    assert not diffs, "\n\n".join(diffs) + "\n\nrun: python docs/readme_examples.py --update"
