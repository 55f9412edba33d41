"""The EtherCAT master side: SOEM (pysoem) driving CiA 402 drives over CoE."""
