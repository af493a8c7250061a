# One image for api, worker and viewer (the command differs). CPU only: the PyTorch CPU wheel is
# installed first, from PyTorch's CPU index, so nothing later can pull a CUDA build.
FROM python:3.11-slim-bookworm

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    VTD_DATA_DIR=/data

RUN pip install --index-url https://download.pytorch.org/whl/cpu torch==2.13.0 \
    && python -c "import torch; assert torch.version.cuda is None, torch.version.cuda"

WORKDIR /app
COPY pyproject.toml README.md ./
COPY storage ./storage
COPY worker ./worker
COPY backend ./backend
COPY webui ./webui
COPY formats ./formats
COPY cli ./cli
# torch==2.13.0 is already satisfied by the +cpu build above, so pip keeps it.
RUN pip install . \
    && python -c "import torch; assert torch.version.cuda is None, 'a CUDA build slipped in'"

RUN useradd --create-home --uid 1000 vtd && mkdir -p /data && chown vtd:vtd /data
USER vtd
VOLUME ["/data"]
EXPOSE 8000
CMD ["vtdslam", "serve", "--host", "0.0.0.0"]
