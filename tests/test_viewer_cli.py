"""``oclgi view`` on the command line: where it listens, and bad input as one
line (the server itself: tests/test_viewer_socket.py, tests/test_viewer_browser.py)."""

import socket

from cli_run import in_process


def test_help_says_it_listens_on_this_machine_only(monkeypatch, capsys, tmp_path):
    r = in_process(monkeypatch, capsys, tmp_path, "view", "--help")
    assert r.returncode == 0
    text = " ".join(r.stdout.split())
    assert "default 127.0.0.1: this machine only" in text and "--port" in text and "--edge" in text


def test_bad_input_is_one_line(monkeypatch, capsys, tmp_path, scenes_dir):
    scene = scenes_dir / "cornell_bunny.toml"
    for args, words in [
        (["view", tmp_path / "missing.toml"], "missing.toml"),
        (["view", scene, "--port", "70000"], "port number"),
        (["view", scene, "--edge", "-1"], "--edge"),
        (["view", scene, "--photons", "0"], "--photons"),
    ]:
        r = in_process(monkeypatch, capsys, tmp_path, *args)
        assert r.returncode == 2, (args, r)
        lines = r.stderr.strip().splitlines()
        assert words in lines[-1] and "Traceback" not in r.stderr, (args, r.stderr)


def test_a_port_in_use_is_one_line(monkeypatch, capsys, tmp_path, scenes_dir):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        r = in_process(monkeypatch, capsys, tmp_path, "view", scenes_dir / "cornell_box.toml", "--port", port,
                       "--photons", "1000", "--edge", "1", "--quiet")
    assert r.returncode == 2 and r.stdout == "", r
    assert r.stderr.startswith(f"oclgi: error: cannot listen on 127.0.0.1:{port}: ") and r.stderr.count("\n") == 1, \
        r.stderr
