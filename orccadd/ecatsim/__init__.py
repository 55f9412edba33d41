"""An EtherCAT slave simulator (issue 45, under way): a chain of ESCs answering a master's
frames on one end of a virtual Ethernet link. So far: the frames and their datagrams."""
