"""The argument parser (colsim.cli.entry): its defaults and help come from the one place each
default lives (colsim.solvers.defaults, colsim.stages.settings), and a bad value stops it
with exit status 2 naming the option."""
import pytest

from colsim.cli import build_parser
from colsim.cli.flags import stage_settings
from colsim.solvers import defaults
from colsim.stages.settings import PackSettings, SolverSettings

COLLAPSE = ["collapse", "--input", "column.nc", "--output", "collapse.nc"]
PACK = ["pack", "--height", "2", "--output", "pack.nc"]


def _help(parser, command: str) -> str:
    subparsers = next(action for action in parser._actions if action.dest == "command")
    return " ".join(subparsers.choices[command].format_help().split())


def test_solver_defaults_and_choices_are_the_defaults_module_s():
    parser = build_parser()
    for args in (COLLAPSE, PACK):
        assert stage_settings(parser.parse_args(args), SolverSettings).solver == defaults.DEFAULT_SOLVER
    text = _help(parser, "collapse")
    assert f"dt/sqrt(h0/g) = {defaults.AUTO_APGD_BELOW:g}" in text
    assert f"under auto {defaults.AUTO_APGD_LENGTH_FLOOR:g}" in text
    assert f"under auto {defaults.AUTO_APGD_OVERLAP_TOLERANCE:g}" in text
    assert "{" + ",".join(defaults.SOLVERS) + "}" in text


def test_pack_defaults_are_the_pack_settings_s():
    chosen = stage_settings(build_parser().parse_args(PACK), PackSettings)
    assert chosen == PackSettings(height=2.0)
    assert (chosen.max_spheres, chosen.layer_height, chosen.freeze_depth) == (500_000, None, 3.5)


@pytest.mark.parametrize("args, option", [(COLLAPSE + ["--solver", "gauss-seidel"], "--solver"),
                                          (COLLAPSE + ["--threads", "0"], "--threads"),
                                          (COLLAPSE + ["--solver-tolerance", "-1"], "--solver-tolerance")])
def test_a_bad_value_exits_2_naming_the_option(args, option, capsys):
    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args(args)
    assert stop.value.code == 2
    assert option in capsys.readouterr().err


@pytest.mark.parametrize("args, said", [
    (COLLAPSE + ["--mu_r", "0.1"], "colsim collapse: error: unrecognized arguments: --mu_r 0.1 (--mu_r: did you mean --mu-r?)"),
    (COLLAPSE + ["--step", "2"], "colsim collapse: error: unrecognized arguments: --step 2 (--step: did you mean --steps?)"),
    (PACK + ["--no-such-flag"], "colsim pack: error: unrecognized arguments: --no-such-flag"),
])
def test_a_flag_misspelt_or_abbreviated_is_refused_by_its_subcommand(args, said, capsys):
    """Issue 79.9: an abbreviation is no flag (`--step 2` was taken for `--steps 2`), and the error
    names the subcommand and the flag meant (it named neither)."""
    from colsim.cli import main
    with pytest.raises(SystemExit) as stopped:
        main(args)
    assert stopped.value.code == 2
    assert capsys.readouterr().err.strip().splitlines()[-1] == said


def test_no_parser_takes_an_abbreviation():
    parser = build_parser()
    assert not parser.allow_abbrev and all(not command.allow_abbrev for command in parser.commands.values())


def test_version_names_the_commit_and_verbosity_goes_anywhere(capsys):
    """Issue 48.8: --version prints the version and the source's commit; -v and -q are accepted
    before or after the subcommand, together refused; each subcommand's help starts with its line."""
    import subprocess
    import sys

    from colsim import __version__
    from colsim.cli.entry import build_parser

    done = subprocess.run([sys.executable, "-m", "colsim.cli", "--version"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.startswith(f"colsim {__version__}, commit ")
    parser = build_parser()
    for argv in (["-v", "mu-r", "--polygon", "6"], ["mu-r", "--polygon", "6", "-v"]):
        args = parser.parse_args(argv)
        assert args.verbose and not args.quiet
    assert parser.parse_args(["mu-r", "--polygon", "6", "-q"]).quiet
    assert not parser.parse_args(["mu-r", "--polygon", "6"]).verbose
    from colsim.cli import main
    assert main(["mu-r", "--polygon", "6", "-q"]) == 0
    with pytest.raises(SystemExit):
        main(["-v", "mu-r", "--polygon", "6", "-q"])
    assert "contradict" in capsys.readouterr().err
    assert parser._subparsers._group_actions[0].choices["pack"].description.startswith("fill a cylinder")


@pytest.mark.parametrize("code, message, words", [
    (2, "Call to cuMemAlloc results in CUDA_ERROR_OUT_OF_MEMORY", ["out of the GPU's memory", "--device cpu"]),
    (700, "Call to cuMemcpyDtoH results in CUDA_ERROR_ILLEGAL_ADDRESS", ["on the GPU: CudaAPIError", "ILLEGAL"]),
])
def test_an_error_of_the_gpu_is_one_line_exit_1(code, message, words, monkeypatch, tmp_path, capsys):
    """numba-cuda's driver errors (here its own CudaAPIError, raised where the command would run) end
    a command with one line naming the GPU and exit 1; any other error is not taken for one."""
    driver = pytest.importorskip("numba.cuda.cudadrv.driver", reason="numba.cuda is not importable")
    from colsim.cli import commands, main

    def fails(args):
        raise driver.CudaAPIError(code, message)

    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(commands, "collapse", fails)
    assert main(COLLAPSE + ["-q"]) == 1
    last = capsys.readouterr().err.strip().splitlines()
    assert len(last) == 1 and last[0].startswith("colsim collapse: failed: ")
    assert all(word in last[0] for word in words), last[0]

    def other(args):
        raise ZeroDivisionError("not the GPU's")

    monkeypatch.setattr(commands, "collapse", other)
    with pytest.raises(ZeroDivisionError):
        main(COLLAPSE + ["-q"])
