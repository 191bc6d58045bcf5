#!/usr/bin/python3
"""Drives swarf's viewer page in a real headless Chromium (selenium).

Run by tests/viewer_browser_test.cc, which starts the viewer and streams the
job; this side speaks on stdout, one line each:
  READY                the page loaded and drew its mesh (stream now)
  SEEN moves           (stream mode, twice) tiles arrived for a state of the
                       job cut up to `moves` (0 < moves < the total, the
                       second above the first): the test paces the job on
                       these lines, not on time
  PROBE x y z          a height read under the pointer (repr floats), for
                       the test to compare with the API's Probe
  OK | FAIL reason     the verdict of the checks made here
Usage: viewer_browser.py URL MOVES_TOTAL SCREENSHOT_PREFIX MODE
MODE: "stream" (the job streams after READY: tiles must arrive meanwhile)
or "done" (the job is finished before the page opens).
"""
import os
import shutil
import sys
import tempfile
import time

from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By

CHROMIUM = '/usr/bin/chromium'
CHROMEDRIVER = '/usr/bin/chromedriver'


def say(line):
    print(line, flush=True)


def fail(reason):
    say('FAIL ' + reason)
    sys.exit(1)


def wait_for(driver, script, what, timeout=60):
    end = time.time() + timeout
    while time.time() < end:
        v = driver.execute_script(script)
        if v:
            return v
        time.sleep(0.05)
    fail('timed out waiting for ' + what)


def severe(driver):
    return [e for e in driver.get_log('browser') if e['level'] == 'SEVERE']


def main():
    url, total, shot, mode = sys.argv[1], int(sys.argv[2]), sys.argv[3], sys.argv[4]
    profile = tempfile.mkdtemp(prefix='swarf-chromium-')
    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for a in ['--headless', '--no-sandbox', '--disable-gpu', '--disable-quic',
              '--no-first-run', '--disable-background-networking',
              '--disable-component-update', '--disable-sync',
              '--user-data-dir=' + profile, '--use-gl=angle',
              '--use-angle=swiftshader', '--enable-unsafe-swiftshader',
              '--window-size=1000,760']:
        opts.add_argument(a)
    opts.set_capability('goog:loggingPrefs', {'browser': 'ALL'})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    try:
        run(driver, url, total, shot, mode)
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def run(driver, url, total, shot, mode):
    driver.get(url)
    wait_for(driver, 'return window.swarf && window.swarf.ready', 'the page')
    s = driver.execute_script('return window.swarf.session')
    tiles = s['tiles_x'] * s['tiles_y']
    stats = wait_for(driver, 'const s = window.swarf.stats; '
                     'return s.frames > 0 && s.meshUpdates > 0 && s', 'the mesh')
    if not 0 < stats['meshes'] <= tiles:
        fail('%d tile meshes for %d tiles' % (stats['meshes'], tiles))
    if not driver.execute_script(
            'return !!document.querySelector("#view canvas").getContext("webgl")'):
        fail('no WebGL context')
    errors = severe(driver)
    if errors:
        fail('console errors after loading: %r' % errors)
    say('READY')

    if mode == 'stream':
        # The job pauses until each line: however slow this page on a busy
        # machine, it must fetch a part-cut state.
        seen = 0
        for _ in range(2):
            seen = wait_for(
                driver, 'for (const e of window.swarf.stats.tileLog) '
                'if (e.tiles > 0 && e.moves > %d && e.moves < %d) '
                'return e.moves; return 0' % (seen, total),
                'tiles while the job streams (after %d moves)' % seen,
                timeout=120)
            say('SEEN %d' % seen)

    # The job ends: every move applied and the page holds the last version.
    wait_for(driver, 'const s = window.swarf.state; return s && s.moves === %d '
             '&& s.version > 0' % total, 'all %d moves' % total, timeout=120)
    wait_for(driver, 'return window.swarf.stats.tileLog.length > 0 && '
             'window.swarf.stats.tileLog.slice(-1)[0].version >= '
             'window.swarf.state.version', 'the last tiles')
    log = driver.execute_script('return window.swarf.stats.tileLog')
    if mode == 'stream':
        during = [e for e in log if e['tiles'] > 0 and 0 < e['moves'] < total]
        if len(during) < 2:
            fail('tiles did not arrive while the job streamed: %r %r' % (log, driver.execute_script('return window.swarf.stats')))
        # Only changed tiles after the first fetch: never the whole grid
        # again (the job cuts a band, not every tile at every step).
        if any(e['tiles'] >= tiles for e in log[1:]):
            fail('a later fetch sent every tile: %r' % log)
    wait_for(driver, 'return window.swarf.stats.pathPoints >= 2', 'the toolpath')

    # Heights under the pointer, through the page's raycast and the Probe RPC.
    canvas = driver.find_element(By.CSS_SELECTOR, '#view canvas')
    readout = driver.find_element(By.ID, 'readout')
    w, h = canvas.size['width'], canvas.size['height']
    for dx, dy in [(0, 0), (w // 8, h // 10), (-w // 7, -h // 12)]:
        before = readout.get_attribute('data-x'), readout.get_attribute('data-y')
        ActionChains(driver).move_to_element_with_offset(canvas, dx, dy).perform()
        end = time.time() + 20
        while time.time() < end:
            now = readout.get_attribute('data-x'), readout.get_attribute('data-y')
            if now[0] is not None and now != before:
                break
            time.sleep(0.05)
        else:
            fail('no height readout under the pointer at offset %d, %d' % (dx, dy))
        x, y, z = (float(readout.get_attribute('data-' + k)) for k in 'xyz')
        say('PROBE %r %r %r' % (x, y, z))
    driver.save_screenshot(shot + '.png')

    # The other layers: error map and cutting marks on, then drawn.
    driver.find_element(By.ID, 'show-marks').click()
    driver.find_element(By.ID, 'show-error').click()
    wait_for(driver, 'return window.swarf.stats.errorMap', 'the error map')
    if s['scheme'] == 'taylor':
        marks = wait_for(driver, 'return window.swarf.stats.marks', 'the marks')
        if marks < 1:
            fail('no cutting marks drawn')
    time.sleep(0.3)
    driver.save_screenshot(shot + '-error-marks.png')
    errors = severe(driver)
    if errors:
        fail('console errors: %r' % errors)
    say('OK')


if __name__ == '__main__':
    if not (os.path.exists(CHROMIUM) and os.path.exists(CHROMEDRIVER)):
        fail('chromium or chromium-driver missing')
    main()
