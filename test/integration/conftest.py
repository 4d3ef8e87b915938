"""Fixtures of the integration tests: a test-side rclpy context on the private domain."""

import shutil

import pytest
from ros_harness import Harness


@pytest.fixture
def listener(ros_domain_id):
    """Yield a :class:`ros_harness.Harness` (probe node, publishers, spin loop); close it."""
    harness = Harness()
    try:
        yield harness
    finally:
        harness.close()


CHROMIUM, CHROMEDRIVER = '/usr/bin/chromium', '/usr/bin/chromedriver'


@pytest.fixture
def browser():
    """Headless Chromium through chromedriver (Debian's packages); quit at teardown."""
    missing = [p for p in (CHROMIUM, CHROMEDRIVER) if not shutil.which(p)]
    if missing:
        pytest.fail(f"the browser tests need Debian's chromium and chromium-driver (missing: "
                    f'{", ".join(missing)}): apt-get install chromium chromium-driver')
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in ('--headless=new', '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader',
                 '--enable-unsafe-swiftshader', '--disable-background-networking',
                 '--disable-component-update', '--disable-sync', '--no-first-run',
                 '--window-size=1280,800', '--force-device-scale-factor=1'):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    try:
        yield driver
    finally:
        driver.quit()
