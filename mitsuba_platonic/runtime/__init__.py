"""The machine a command runs on: Dr.Jit's backend (:mod:`.backend`: a working LLVM or CUDA, checked
before Dr.Jit loads), its memory and disk (:mod:`.budget`: will it fit) and progress output
(:mod:`.progress`: bars on a terminal, plain lines in a log). Imports neither torch nor Dr.Jit here."""
