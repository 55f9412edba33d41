"""An EtherCAT slave simulator (`python -m orccadd.ecatsim`): a line of ESCs answering a master's
frames on one end of a virtual Ethernet link, each with a CoE mailbox over a CiA 402 drive's
dictionary and the drive simulator's axis on the shared arm (docs/simulators.md)."""
