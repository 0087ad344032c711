"""pytest imports test files by basename (the test folders are no packages): two test files of one name in two
layers stop the whole collection, so every name is unique."""

from collections import Counter

from conftest import REPO


def test_every_test_file_name_is_unique_across_the_layers():
    names = Counter(p.name for p in (REPO / "tests").rglob("test_*.py"))
    assert not [n for n, k in names.items() if k > 1]
