# swarf add-on (client/freecad): nothing to set up without the GUI; the
# headless entry is simulate-job (swarf_freecad/headless.py).
