# One image for every fleet process; each compose.yaml service runs one `fleet <verb>`.
# Build: docker build -t fleet:local .   Run one process: docker run --rm fleet:local fleet --help
FROM python:3.12-slim

ENV PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1

WORKDIR /opt/fleet
COPY pyproject.toml README.md ./
COPY fleet fleet
COPY configs configs
COPY agents agents
COPY sim_server sim_server
COPY planners planners
RUN pip install . \
    && useradd --create-home --uid 1000 fleet \
    && mkdir /data \
    && chown fleet /data

USER fleet
WORKDIR /data
# the router's TCP endpoint (fleet router --listen tcp/0.0.0.0:7447)
EXPOSE 7447
CMD ["fleet", "--help"]
