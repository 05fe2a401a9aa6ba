"""The arm's side: wire protocol, serial link, streamer, firmware simulator, port discovery."""
