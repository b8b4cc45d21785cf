# trackvkf image: API (trackvkf serve), worker (trackvkf worker) and migrations (trackvkf migrate).
FROM python:3.11-slim

ENV PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1

WORKDIR /srv/trackvkf
# Pango (and a font) for WeasyPrint: the planning report's PDF (GET /condition/report.pdf)
RUN apt-get update \
    && apt-get install -y --no-install-recommends libpango-1.0-0 libpangoft2-1.0-0 libharfbuzz-subset0 fonts-dejavu-core \
    && rm -rf /var/lib/apt/lists/*
COPY pyproject.toml README.md alembic.ini ./
COPY app ./app
COPY worker ./worker
COPY migrations ./migrations
# editable install: the migrations directory is found next to the package
RUN pip install -e . \
    && useradd --create-home --uid 10001 trackvkf \
    && mkdir -p /data/runs \
    && chown trackvkf /data/runs

USER trackvkf
ENV TRACKVKF_RUN_STORE=/data/runs
VOLUME ["/data/runs"]
EXPOSE 8000
CMD ["trackvkf", "serve", "--host", "0.0.0.0", "--port", "8000"]
