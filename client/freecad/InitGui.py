# swarf add-on: registers "Simulate with swarf" (shown in the Path workbench
# of FreeCAD 0.20 and the CAM workbench of 1.0) and its preferences page.
# FreeCAD puts this folder on sys.path before running this file.
import swarf_freecad.gui

swarf_freecad.gui.register()
