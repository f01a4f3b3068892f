"""``ttes crowd``: a moderngl renderer for thousands of soldiers fed by the server's update stream."""
