"""One module per fuzz target; the interface is in fuzz/README.md. The runner finds every module here."""
