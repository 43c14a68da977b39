"""Headless Chromium driven over the DevTools protocol, standard library only.

For the browser tests of the 3D viewer and the screenshots of the docs:
Debian's ``chromium`` (``tools/misc/setup_browser.sh`` installs it) is
started with ``--remote-debugging-pipe`` and spoken to over two pipes
(NUL-terminated JSON, the protocol ChromeDriver and Puppeteer use), so no
websocket client, no driver binary and no browser download are needed.

The flags keep it quiet on a machine without network (without the
background-networking ones it floods a closed network with connection
attempts) and ask for software WebGL (SwiftShader through ANGLE: headless
Chromium has no GPU here). Chromium 156 falls back to SwiftShader without
the two SwiftShader flags too (checked 2026-11-28); they keep the tests
working where a release stops falling back by itself.
"""
import base64
import fcntl
import io
import json
import os
import shutil
import subprocess
import tempfile
import threading
import time
from typing import Dict, List, Optional

import numpy as np

#: Flags of every start (the user data folder, the pipe and the window
#: size are added).
CHROMIUM_FLAGS = (
    '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic',
    '--no-first-run', '--disable-background-networking',
    '--disable-component-update', '--disable-sync',
    '--disable-default-apps', '--disable-extensions', '--mute-audio',
    '--hide-scrollbars', '--use-angle=swiftshader',
    '--enable-unsafe-swiftshader', '--allow-file-access-from-files')
#: Why the browser tests skip where no Chromium is installed.
MISSING_REASON = ('Debian chromium is not installed (tools/misc/'
                  'setup_browser.sh installs it when run as root)')


def chromium_binary() -> Optional[str]:
    """The Chromium executable on PATH, or None."""
    for name in ('chromium', 'chromium-browser', 'google-chrome'):
        found = shutil.which(name)
        if found:
            return found
    return None


class BrowserError(RuntimeError):
    """The browser died, answered with an error, or timed out."""


class HeadlessChromium:
    """One headless Chromium with one page.

    Use as a context manager; :meth:`close` ends the browser and removes
    its profile.

    Args:
        width (int): Viewport width, CSS pixels. Defaults to 1280.
        height (int): Viewport height. Defaults to 800.
        binary (str, optional): Executable. Defaults to
            :func:`chromium_binary`.
        timeout (float): Seconds to wait for one answer. Defaults to 60.

    Raises:
        BrowserError: If no Chromium is found or it does not start.
    """

    def __init__(self, width: int = 1280, height: int = 800,
                 binary: Optional[str] = None,
                 timeout: float = 60.0) -> None:
        binary = binary or chromium_binary()
        if binary is None:
            raise BrowserError(MISSING_REASON)
        self.timeout = timeout
        self.profile = tempfile.mkdtemp(prefix='occ-chromium-')
        # Chromium reads commands on fd 3 and answers on fd 4.
        to_browser, self._out = os.pipe()
        self._in, from_browser = os.pipe()
        # Numbers above 4, so that bash's `3<&A 4>&B` never clobbers one
        # with the other.
        child = [fcntl.fcntl(fd, fcntl.F_DUPFD, 10)
                 for fd in (to_browser, from_browser)]
        for fd in (to_browser, from_browser):
            os.close(fd)
        command = [binary, *CHROMIUM_FLAGS, f'--user-data-dir={self.profile}',
                   '--remote-debugging-pipe',
                   f'--window-size={width},{height}', 'about:blank']
        self.proc = subprocess.Popen(
            ['bash', '-c', f'exec "$@" 3<&{child[0]} 4>&{child[1]}',
             'chromium', *command],
            pass_fds=child, stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        for fd in child:
            os.close(fd)
        self._next_id = 0
        self._answers: Dict[int, dict] = {}
        self._events: List[dict] = []
        self._cond = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.session = None
        target = self.send('Target.createTarget', url='about:blank')
        self.session = self.send('Target.attachToTarget',
                                 targetId=target['targetId'],
                                 flatten=True)['sessionId']
        for domain in ('Page', 'Runtime', 'Network'):
            self.send(f'{domain}.enable')
        self.send('Emulation.setDeviceMetricsOverride', width=width,
                  height=height, deviceScaleFactor=1, mobile=False)

    # The protocol -------------------------------------------------------
    def _read(self) -> None:
        buffer = b''
        with os.fdopen(self._in, 'rb', buffering=0) as pipe:
            while True:
                chunk = pipe.read(1 << 16)
                if not chunk:
                    break
                buffer += chunk
                *messages, buffer = buffer.split(b'\0')
                with self._cond:
                    for raw in messages:
                        message = json.loads(raw)
                        if 'id' in message:
                            self._answers[message['id']] = message
                        else:
                            self._events.append(message)
                    self._cond.notify_all()
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def send(self, method: str, **params) -> dict:
        """Send one command and wait for its answer.

        Returns:
            dict: The answer's ``result``.

        Raises:
            BrowserError: On an error answer, a dead browser or a timeout.
        """
        self._next_id += 1
        ident = self._next_id
        message = dict(id=ident, method=method, params=params)
        if self.session is not None and not method.startswith('Target.'):
            message['sessionId'] = self.session
        os.write(self._out, json.dumps(message).encode() + b'\0')
        deadline = time.monotonic() + self.timeout
        with self._cond:
            while ident not in self._answers:
                left = deadline - time.monotonic()
                if getattr(self, '_closed', False) or left <= 0:
                    raise BrowserError(
                        f'{method}: no answer from Chromium '
                        f'({"it exited" if self.proc.poll() is not None else "timeout"})'  # noqa: E501
                        f'; stderr: {self._stderr_tail()}')
                self._cond.wait(left)
            answer = self._answers.pop(ident)
        if 'error' in answer:
            raise BrowserError(f'{method}: {answer["error"]}')
        return answer.get('result', {})

    def _stderr_tail(self) -> str:
        if self.proc.poll() is None or self.proc.stderr is None:
            return '(running)'
        return self.proc.stderr.read().decode(errors='replace')[-2000:]

    def events(self, method: str) -> List[dict]:
        """The parameters of every event ``method`` received so far."""
        with self._cond:
            return [e['params'] for e in self._events
                    if e.get('method') == method]

    # The page -----------------------------------------------------------
    def evaluate(self, expression: str, await_promise: bool = True):
        """The value of a JavaScript expression in the page.

        Raises:
            BrowserError: If it throws (its message included).
        """
        result = self.send('Runtime.evaluate', expression=expression,
                           awaitPromise=await_promise, returnByValue=True)
        if 'exceptionDetails' in result:
            details = result['exceptionDetails']
            text = details.get('exception', {}).get(
                'description', details.get('text'))
            raise BrowserError(f'{expression[:80]}: {text}')
        return result['result'].get('value')

    def navigate(self, url: str) -> None:
        """Open ``url`` (and wait until the document exists)."""
        answer = self.send('Page.navigate', url=url)
        if answer.get('errorText'):
            raise BrowserError(f'{url}: {answer["errorText"]}')
        self.wait_for('document.readyState !== "loading"')

    def wait_for(self, condition: str, timeout: Optional[float] = None,
                 interval: float = 0.05):
        """Poll a JavaScript expression until it is truthy.

        Returns:
            The truthy value.

        Raises:
            BrowserError: After ``timeout`` seconds (default: the
                browser's), with the page's errors.
        """
        deadline = time.monotonic() + (timeout or self.timeout)
        while True:
            value = self.evaluate(condition)
            if value:
                return value
            if time.monotonic() > deadline:
                raise BrowserError(f'timed out waiting for {condition!r}; '
                                   f'page errors: {self.page_errors()}')
            time.sleep(interval)

    def page_errors(self) -> List[str]:
        """Uncaught exceptions and ``console.error`` lines of the page."""
        errors = [
            e['exceptionDetails'].get('exception', {}).get(
                'description', e['exceptionDetails'].get('text', ''))
            for e in self.events('Runtime.exceptionThrown')
        ]
        errors += [
            ' '.join(str(a.get('value', a.get('description', '')))
                     for a in e['args'])
            for e in self.events('Runtime.consoleAPICalled')
            if e['type'] == 'error'
        ]
        return errors

    def requested_urls(self) -> List[str]:
        """Every URL the page asked for since the start."""
        return [e['request']['url']
                for e in self.events('Network.requestWillBeSent')]

    def screenshot(self) -> np.ndarray:
        """The viewport as RGB, Shape (H, W, 3), uint8."""
        from PIL import Image
        data = self.send('Page.captureScreenshot', format='png')['data']
        with Image.open(io.BytesIO(base64.b64decode(data))) as image:
            return np.asarray(image.convert('RGB'))

    def mouse_move(self, x: float, y: float) -> None:
        """Move the pointer to viewport pixel ``(x, y)``."""
        self.send('Input.dispatchMouseEvent', type='mouseMoved', x=x, y=y)

    def close(self) -> None:
        """End the browser and remove its profile."""
        if self.proc.poll() is None:
            try:
                self.send('Browser.close')
            except BrowserError:
                pass
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        try:
            os.close(self._out)
        except OSError:
            pass
        shutil.rmtree(self.profile, ignore_errors=True)

    def __enter__(self) -> 'HeadlessChromium':
        return self

    def __exit__(self, *exc) -> None:
        self.close()
