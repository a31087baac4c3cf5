# smoothfleet server image: API, dashboard, planner and the simulated fleet share it.
FROM python:3.11-slim-bookworm AS build
WORKDIR /src
COPY pyproject.toml README.md ./
COPY smoothfleet ./smoothfleet
COPY contract ./contract
COPY app ./app
COPY planner ./planner
COPY dashboards ./dashboards
COPY vehicle_agent ./vehicle_agent
COPY sim ./sim
COPY migrations ./migrations
COPY seed_data ./seed_data
RUN pip wheel --no-cache-dir --wheel-dir /wheels '.[server]'

FROM python:3.11-slim-bookworm
RUN useradd --create-home --uid 10001 smoothfleet \
    && mkdir /data && chown smoothfleet:smoothfleet /data
COPY --from=build /wheels /wheels
RUN pip install --no-cache-dir --no-index --find-links /wheels 'smoothfleet[server]' \
    && rm -rf /wheels
USER smoothfleet
# Files the commands write (the MOTION store, a dump given a relative name) go to /data,
# compose's `smoothfleet-data` volume: in `/`, the user could write none, and in the container's
# own layer they went with it.
WORKDIR /data
ENV PYTHONUNBUFFERED=1 \
    SMOOTHFLEET_HOST=0.0.0.0 \
    SMOOTHFLEET_PORT=8000 \
    SMOOTHFLEET_DATA_DIR=/data
EXPOSE 8000
# The start period covers the migrations `serve` runs first (an audit saw 28 s on a fresh
# database on a loaded 2-core machine; `serve` gives its workers 120 s): without it three
# failed checks, 30 s, could mark the api unhealthy before it served, and compose gave up on
# the services waiting for it.
HEALTHCHECK --interval=10s --timeout=3s --retries=3 --start-period=120s \
    CMD python -c "import httpx,sys; sys.exit(httpx.get('http://127.0.0.1:8000/readyz').status_code != 200)"
ENTRYPOINT ["smoothfleet"]
CMD ["serve"]
