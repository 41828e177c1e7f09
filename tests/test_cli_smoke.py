from conftest import assert_user_error


def test_help_lists_commands(run_cli):
    res = run_cli("--help")
    assert res.code == 0
    for command in ("import", "info"):
        assert command in res.out


def test_info_on_missing_file_is_one_line(run_cli, tmp_path):
    res = run_cli("info", tmp_path / "nope.h5")
    assert_user_error(res, "nope.h5", "no such file")


def test_version(run_cli):
    from primspace import __version__

    res = run_cli("--version")
    assert res.code == 0 and res.out.strip() == f"primspace {__version__}"
