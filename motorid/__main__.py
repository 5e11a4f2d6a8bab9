from motorid.cli import console

console()
