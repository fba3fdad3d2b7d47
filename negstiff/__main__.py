from negstiff.cli import run

run()
