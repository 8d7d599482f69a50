"""``aoc index --neighbours`` (the neighbour rule) is not the ``--candidates`` of rollout,
explain and evaluate (K candidate actions); ``aoc index --candidates`` still works, hidden."""


def test_index_help_names_neighbours_and_hides_the_old_spelling(aoc_inproc):
    code, out, _err = aoc_inproc("index", "--help")
    assert code == 0
    assert "--neighbours" in out and "--candidates" not in out


def test_the_old_and_new_spelling_must_agree(aoc_inproc, store):
    code, out, err = aoc_inproc("index", "x", "--neighbours", "nearest",
                                "--candidates", "per_action")
    assert code == 2 and out == "" and err.count("\n") == 1
    assert "--neighbours and --candidates" in err


def test_the_old_spelling_is_still_a_checked_choice(aoc_inproc, store):
    code, _out, err = aoc_inproc("index", "x", "--candidates", "sideways")
    assert code == 2 and "'sideways' is not one of" in err
