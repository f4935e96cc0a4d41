"""cli.setup_logging: one line per record, level, component and event first, for a journal filter."""
import io
import logging
import os

from edge_runtime import cli


def test_records_are_single_filterable_lines():
    out = io.StringIO()
    cli.setup_logging(stream=out)
    try:
        logging.getLogger("edge_runtime.core.service").warning("notify failed:\nno socket", extra={"event": "notify"})
        logging.getLogger("edge_runtime.robot").info("up")
    finally:
        cli.setup_logging()
    assert out.getvalue().splitlines() == [
        "level=WARNING component=edge_runtime.core.service event=notify notify failed: | no socket",
        "level=INFO component=edge_runtime.robot event=log up",
    ]


def test_the_journal_gets_the_syslog_priority_prefix(tmp_path, monkeypatch):
    with open(tmp_path / "journal", "w") as stream:
        st = os.fstat(stream.fileno())
        monkeypatch.setenv("JOURNAL_STREAM", f"{st.st_dev}:{st.st_ino}")
        assert cli._is_journal(stream)
        record = logging.LogRecord("edge_runtime.wearable", logging.ERROR, __file__, 1, "bus down", None, None)
        assert cli.OneLineFormatter(journal=True).format(record) == \
            "<3>level=ERROR component=edge_runtime.wearable event=log bus down"
    monkeypatch.setenv("JOURNAL_STREAM", "1:2")
    assert not cli._is_journal(io.StringIO())
