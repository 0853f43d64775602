"""``rcp bench fuzz``: the REST surface fuzzed from its own OpenAPI schema (schemathesis) against a real server
on loopback, with a random seed and as many examples as asked; it prints every failure it finds (a 5xx, an
answer the schema does not declare, one past the time limit) with the curl command that repeats it.

The test suite (``tests/service/test_schema.py``) runs the same configuration, :func:`fuzz_config`, with a
fixed seed, derandomized and without learning from the server's answers, so that a fresh clone and CI get the
same verdict; this is the longer, random run that looks for the next failure to add there.
"""

from __future__ import annotations

import random
import time

from ..service.loopback import BackgroundServer

TOKEN = "fuzz-token"  # schemathesis brings it, and checks that requests without it or with another get 401
AUTH = {"authorization": f"Bearer {TOKEN}"}
TIMEOUT = 30  # seconds an answer may take; the largest painting the limits allow (MAX_WORK rays) takes about 4
MAX_PIXELS = 64 * 64
MAX_WORK = 1 << 24  # 64x64 pixels x 64 iterations x 64 spp
SIZES = [1, 7, 16, 64]  # widths and heights whose products stay within MAX_PIXELS
SERVER_SETTINGS = {
    "max_pixels": MAX_PIXELS,
    "max_work": MAX_WORK,
    "max_video_work": 4 * MAX_WORK,
    "max_print_work": 0,
    "token": TOKEN,
}
"""The server fuzzed: every painting that passes is cheap, a video at most a few small paintings' work; no print
(its bodies checked, every one refused at the work limit: a print's queue would fill with fuzzed ones)."""


def fuzz_config(scenes: list[str], seed: int, examples: int, deterministic: bool) -> dict:
    """Schemathesis's configuration, as a dict for ``schemathesis.Config.from_dict``. Two things the schema
    cannot say are told to the generator: scene names are data (most bodies' ``scene`` is one of ``scenes``),
    and ``width * height`` must stay under ``MAX_PIXELS`` (small sizes are drawn often; a schema-valid body
    may still get the documented 422). ``deterministic``: the same requests on every run (Hypothesis
    derandomized, and nothing learnt from the answers, whose ids and timings differ from run to run)."""
    learn = {"extra-data-sources": {"responses": not deterministic}}
    return {
        "seed": seed,
        "generation": {"max-examples": examples, "database": "none", "deterministic": deterministic},
        "phases": {
            "examples": learn,
            "coverage": learn,
            "fuzzing": {**learn, "error-feedback": {"enabled": not deterministic}},
            "stateful": {"enabled": False},
        },
        "request-timeout": TIMEOUT,
        "auth": {"openapi": {"HTTPBearer": {"bearer": TOKEN}, "APIKeyQuery": {"api_key": TOKEN}}},
        "dictionaries": {"scenes": {"values": sorted(scenes)}, "sizes": {"values": SIZES}},
        "parameters": {
            "body.scene": {"dictionary": "scenes", "probability": 0.9},
            "body.width": {"dictionary": "sizes", "probability": 0.5},
            "body.height": {"dictionary": "sizes", "probability": 0.5},
        },
        "checks": {
            # a schema-valid body may name an unknown scene (404) or, through width * height, an eye on its
            # look_at point or an up along the view, ask for a painting the server cannot make (422)
            # (and a video's path of many keyframes may be longer than RCP_MAX_BODY_BYTES: 413); a valid name
            # may be one of the operator's scenes, which cannot be deleted (403)
            "positive_data_acceptance": {"expected-statuses": ["2xx", 403, 404, 413, 422]},
            # a body past RCP_MAX_BODY_BYTES is turned away before it is read (a video path with more than
            # the keyframes allowed cannot be written shorter): 413 refuses it as surely as 422
            "negative_data_rejection": {"expected-statuses": [400, 401, 403, 404, 405, 406, 409, 413, 415, 422]},
        },
    }


def open_schema(server: BackgroundServer, seed: int, examples: int, deterministic: bool):
    """The server's schema, read from its ``/openapi.json``, with :func:`fuzz_config`."""
    import schemathesis

    scenes = list(server.app.state.service.scenes)
    config = schemathesis.Config.from_dict(fuzz_config(scenes, seed, examples, deterministic))
    return schemathesis.openapi.from_url(f"{server.url}/openapi.json", config=config, timeout=TIMEOUT, headers=AUTH)


def fuzz(examples: int, seed: int | None = None) -> int:
    """Fuzz a fresh server with ``examples`` examples an operation; prints what it finds, returns how many
    distinct failures (operation and kind) there were."""
    from schemathesis import engine
    from schemathesis.engine import Status, events

    seed = random.SystemRandom().randrange(1 << 32) if seed is None else seed
    print(f"rcp bench fuzz: seed {seed}, {examples} examples an operation (repeat: --seed {seed})", flush=True)
    found: dict[tuple[str, str], str] = {}
    clock = time.monotonic()
    with BackgroundServer(**SERVER_SETTINGS) as server:
        for event in engine.from_schema(open_schema(server, seed, examples, deterministic=False)).execute():
            if isinstance(event, events.ScenarioFinished) and event.status == Status.FAILURE:
                for checks in event.recorder.checks.values():
                    for check in checks:
                        info = check.failure_info
                        key = (event.label or "?", info.failure.title if info else check.name)
                        if info is not None and key not in found:
                            found[key] = f"{info.failure.message.strip()}\n    {info.code_sample}"
                            print(f"FAILED {key[0]}: {key[1]}\n    {found[key]}", flush=True)
            elif isinstance(event, events.NonFatalError):
                print(f"ERROR {event.label}: {event.info.message}", flush=True)
            elif isinstance(event, events.EngineFinished):
                break
    seconds = time.monotonic() - clock
    print(f"rcp bench fuzz: {len(found)} distinct failures in {seconds:.0f} s (seed {seed})")
    return len(found)
