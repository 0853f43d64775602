# rcp serve in a container: the walk-through client at /, REST renders under /api, the WebSocket at /ws.
#   docker build -t rcp . && docker run --rm -p 8000:8000 rcp
# Uploads and videos live in the volume at /var/lib/rcp (RCP_DATA): `-v rcp-data:/var/lib/rcp` keeps them.
# Settings are RCP_* environment variables (rcp_server/service/settings.py), e.g. -e RCP_THREADS=4.
# With Ray (deploy/raycluster.yaml runs it on KubeRay): docker build --build-arg EXTRAS=cluster-node -t rcp:ray .

# ---- builder: the project and its dependencies in a venv (no test extras) ----
FROM python:3.11-slim AS builder
ARG EXTRAS=""
ENV PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1
RUN python -m venv /opt/venv
ENV PATH=/opt/venv/bin:$PATH
WORKDIR /src
COPY pyproject.toml README.md ./
COPY rcp_server/ rcp_server/
RUN pip install --upgrade pip && pip install ".${EXTRAS:+[$EXTRAS]}" \
 && pip uninstall -y pip setuptools  # the runtime installs nothing
WORKDIR /

# ---- runtime: the venv, the scenes and the client, run by a user without privileges ----
FROM python:3.11-slim
ARG EXTRAS=""
# KubeRay's probes of a Ray pod call wget: only an image with Ray gets it
RUN if [ -n "$EXTRAS" ]; then apt-get update && apt-get install -y --no-install-recommends wget \
    && rm -rf /var/lib/apt/lists/*; fi
# fixed ids, so that a mounted volume can be given to the group (Kubernetes: securityContext.fsGroup 10001)
RUN groupadd --gid 10001 rcp \
 && useradd --uid 10001 --gid rcp --create-home --home-dir /home/rcp rcp \
 && mkdir -p /var/cache/rcp/numba /var/lib/rcp && chown -R rcp:rcp /var/cache/rcp /var/lib/rcp
# a login shell's /etc/profile sets PATH anew (KubeRay starts Ray with `bash -lc`): it finds the venv here too
RUN echo 'PATH=/opt/venv/bin:$PATH' >/etc/profile.d/venv.sh
COPY --from=builder /opt/venv /opt/venv
COPY scenes/ /opt/rcp/scenes/
COPY client/ /opt/rcp/client/
ENV PATH=/opt/venv/bin:$PATH \
    PYTHONUNBUFFERED=1 \
    RCP_HOST=0.0.0.0 \
    RCP_PORT=8000 \
    RCP_SCENES=/opt/rcp/scenes \
    RCP_CLIENT=/opt/rcp/client \
    RCP_DATA=/var/lib/rcp \
    NUMBA_CACHE_DIR=/var/cache/rcp/numba
USER rcp
WORKDIR /home/rcp
# Compile numba's kernels now, as the user that serves, with the warm-up `rcp serve` runs as it starts (every
# scene's, painting/warmup.py): a container is then ready within seconds. (The cache is keyed on the CPU: on a
# host of another CPU model the server answers at once all the same, 503 "starting" while they compile again.)
RUN rcp scenes && rcp compile
# uploads, videos and their records (service/store.py): mount a volume here to keep them across containers
#   docker run -v rcp-data:/var/lib/rcp -p 8000:8000 rcp
VOLUME ["/var/lib/rcp"]
EXPOSE 8000
# the port comes from RCP_PORT when the check runs, so `-e RCP_PORT=9000` keeps the check right
HEALTHCHECK --interval=30s --timeout=5s --start-period=120s --retries=3 \
  CMD ["python", "-c", "import os, urllib.request; urllib.request.urlopen('http://127.0.0.1:%s/api/health' % os.environ.get('RCP_PORT', '8000'), timeout=4)"]
CMD ["rcp", "serve"]
