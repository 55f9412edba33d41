"""`orccadctl`'s commands that need no daemon (check, graph, export, modules, plot): they load the
compiler, the robot model and plotting, which the online commands (`orccadd.ctl`) never do."""
