"""The TTES stub image generator (pyrender). Never imports `server`."""
