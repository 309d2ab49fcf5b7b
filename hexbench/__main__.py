from hexbench.cli import app

app(prog_name="hexbench")
