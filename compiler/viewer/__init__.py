"""``sofac view``: an interactive window on a running simulation (window), and its command line
(cli). ``sofac.view(sim)`` opens one from Python."""
