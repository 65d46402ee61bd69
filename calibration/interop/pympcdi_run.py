# Runs PyMPCDI's main.py unchanged, except that its off-screen window (placed at 12000,12000
# so that nothing shows) is placed on the virtual screen: Xvfb never exposes a window outside
# its screen, so PyMPCDI's display callback, which saves the output image, would never run.
import runpy, sys
import OpenGL.GLUT as glut
_place = glut.glutInitWindowPosition
glut.glutInitWindowPosition = lambda x, y: _place(0, 0)
sys.path.insert(0, ".")
sys.argv = ["main.py"] + sys.argv[1:]
runpy.run_path("main.py", run_name="__main__")
