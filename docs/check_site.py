"""Opens every page of the built site in headless Chromium, as a reader would, and fails on what a reader would see.

    python docs/check_site.py site            # after: mkdocs build --strict

The site is served over a local HTTP server (relative links and images resolve as on a web host) and driven by
Selenium with Debian's ``chromium`` and ``chromium-driver`` (no browser is downloaded). A page fails when:

- it does not render: no title, or no article with text in it;
- the browser logs an error on its console (a script error, a resource that failed to load);
- an image on it does not load (not complete, or no width);
- a link on it to another page of the site, or to one of its files, does not answer 200.

Screenshots of the home page and of one guide are saved under ``SITE/_screenshots/``.
"""

from __future__ import annotations

import argparse
import functools
import http.server
import shutil
import sys
import threading
import time
import urllib.error
import urllib.parse
import urllib.request
from pathlib import Path

from selenium import webdriver
from selenium.webdriver.chrome.service import Service

SCREENSHOTS = {"home.png": "", "guide.png": "getting-started/"}
BROWSERS = ("chromium", "chromium-browser", "google-chrome")
IMAGES_LOADED = """
return Array.from(document.images).filter(i => !(i.complete && i.naturalWidth > 0))
                                  .map(i => i.getAttribute('src'));
"""


class QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, format, *args):  # noqa: A002 - the base class's name
        pass


class Server(http.server.ThreadingHTTPServer):
    def handle_error(self, request, client_address):
        if not isinstance(sys.exc_info()[1], ConnectionError):  # a browser that stops a load closes its socket
            super().handle_error(request, client_address)


def serve(site: Path) -> tuple[http.server.ThreadingHTTPServer, str]:
    """The site on a free port of the loopback interface, served from a thread."""
    handler = functools.partial(QuietHandler, directory=str(site))
    server = Server(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}/"


def browser() -> webdriver.Chrome:
    """Headless Chromium from the system's packages, its console log kept."""
    binary = next((shutil.which(b) for b in BROWSERS if shutil.which(b)), None)
    driver_path = shutil.which("chromedriver")
    if binary is None or driver_path is None:
        sys.exit("check_site: needs chromium and chromedriver (Debian: apt-get install chromium chromium-driver)")
    options = webdriver.ChromeOptions()
    options.binary_location = binary
    for argument in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                     "--window-size=1440,900", "--hide-scrollbars", "--no-first-run",
                     "--disable-background-networking", "--disable-component-update"):
        options.add_argument(argument)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(executable_path=driver_path), options=options)


def pages(site: Path) -> list[str]:
    """Site-relative URLs of every page (``use_directory_urls``: a folder with an index.html)."""
    found = []
    for index in sorted(site.rglob("index.html")):
        relative = index.parent.relative_to(site).as_posix()
        if relative.startswith("_") or "assets" in relative.split("/"):
            continue
        found.append("" if relative == "." else relative + "/")
    return found


def wait_until_loaded(driver: webdriver.Chrome, timeout: float = 20.0) -> None:
    end = time.time() + timeout
    while time.time() < end:
        if driver.execute_script("return document.readyState") == "complete":
            return
        time.sleep(0.05)
    raise TimeoutError("the page did not finish loading")


def status(url: str) -> int:
    try:
        with urllib.request.urlopen(urllib.request.Request(url, method="GET"), timeout=10) as response:
            return response.status
    except urllib.error.HTTPError as error:
        return error.code
    except OSError:
        return 0


def check_page(driver: webdriver.Chrome, base: str, path: str, links: set[str]) -> list[str]:
    """Problems a reader would see on one page (and the same-site links it holds, added to ``links``)."""
    problems = []
    driver.get_log("browser")  # what an earlier page left
    driver.get(base + path)
    wait_until_loaded(driver)
    if not driver.title.strip():
        problems.append("no title")
    text = driver.execute_script("const a = document.querySelector('article'); return a ? a.innerText : '';")
    if len(text.strip()) < 40:
        problems.append("no article text: the page did not render")
    # images below the fold load lazily in some browsers: bring each into view first
    driver.execute_script("document.querySelectorAll('img').forEach(i => { i.loading = 'eager'; });")
    end = time.time() + 10
    broken = driver.execute_script(IMAGES_LOADED)
    while broken and time.time() < end:
        time.sleep(0.1)
        broken = driver.execute_script(IMAGES_LOADED)
    problems += [f"image does not load: {src}" for src in broken]
    for entry in driver.get_log("browser"):
        if entry.get("level") == "SEVERE":
            problems.append(f"console error: {entry.get('message')}")
    for href in driver.execute_script("return Array.from(document.querySelectorAll('a[href]'), a => a.href);"):
        if href.startswith(base):
            links.add(urllib.parse.urldefrag(href)[0])
    return problems


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("site", nargs="?", default="site", help="the built site (mkdocs build's site_dir)")
    args = parser.parse_args()
    site = Path(args.site).resolve()
    if not (site / "index.html").exists():
        sys.exit(f"check_site: no built site at {site} (run mkdocs build first)")
    start = time.time()
    server, base = serve(site)
    driver = browser()
    failures: dict[str, list[str]] = {}
    links: set[str] = set()
    try:
        driver.set_page_load_timeout(30)
        urls = pages(site)
        for path in urls:
            problems = check_page(driver, base, path, links)
            if problems:
                failures[path or "/"] = problems
        shots = site / "_screenshots"
        shots.mkdir(exist_ok=True)
        for name, path in SCREENSHOTS.items():
            driver.get(base + path)
            wait_until_loaded(driver)
            time.sleep(0.3)  # web fonts and the theme's layout settle
            driver.save_screenshot(str(shots / name))
        for link in sorted(links):
            code = status(link)
            if code != 200:
                failures.setdefault("links", []).append(f"{link.removeprefix(base)}: HTTP {code}")
    finally:
        driver.quit()
        server.shutdown()
    for page, problems in failures.items():
        for problem in problems:
            print(f"check_site: {page}: {problem}")
    print(f"check_site: {len(urls)} pages and {len(links)} site links checked in {time.time() - start:.1f} s; "
          f"screenshots in {site / '_screenshots'}; {'FAILED' if failures else 'all good'}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
