# swarf: the swarfd server and the swarf CLI on Debian bookworm.
#
#   docker build -t swarf .
#   docker run -p 127.0.0.1:50051:50051 -v swarf-data:/var/lib/swarf \
#     -e FLAGS_insecure_public=true swarf
#
# Extra swarfd flags go after the image name (e.g. --max_sessions 64). See
# deploy/README.md for compose (3 replicas behind nginx) and Kubernetes.

# ---------------------------------------------------------------- build
FROM debian:bookworm AS build
WORKDIR /src
# The README's dependency script, alone first so that its layer is cached
# while only the sources change.
COPY scripts/install-deps scripts/install-deps
RUN scripts/install-deps && rm -rf /var/lib/apt/lists/*
COPY . .
RUN cmake -S . -B /build -G Ninja -DCMAKE_BUILD_TYPE=Release \
 && cmake --build /build --target swarfd swarf \
 && strip /build/bin/swarfd /build/bin/swarf \
 && deploy/docker/runtime-packages /build/bin/swarfd /build/bin/swarf \
      > /build/runtime-packages \
 && echo fonts-dejavu-core >> /build/runtime-packages \
 && cat /build/runtime-packages

# -------------------------------------------------------------- runtime
FROM debian:bookworm-slim
# Only the shared libraries the two binaries load (listed by the build stage
# from their ldd output: gRPC, protobuf, abseil, spdlog, SQLite, libpng,
# cairo, ...) and the font the picture labels use.
COPY --from=build /build/runtime-packages /tmp/runtime-packages
RUN apt-get update \
 && xargs -a /tmp/runtime-packages apt-get install -y --no-install-recommends \
 && rm -rf /var/lib/apt/lists/* /tmp/runtime-packages \
 && groupadd --gid 10001 swarf \
 && useradd --uid 10001 --gid swarf --no-create-home --home-dir /var/lib/swarf \
      --shell /usr/sbin/nologin swarf \
 && mkdir -p /var/lib/swarf && chown swarf:swarf /var/lib/swarf
COPY --from=build /build/bin/swarfd /build/bin/swarf /usr/local/bin/

USER swarf:swarf
WORKDIR /var/lib/swarf
# Sessions are journaled here (swarfd --data_dir) and restored on restart.
VOLUME /var/lib/swarf
EXPOSE 50051
HEALTHCHECK --interval=10s --timeout=5s --start-period=20s --retries=3 \
  CMD ["swarf", "health", "--server", "127.0.0.1:50051", "--timeout", "3"]
# swarfd drains on SIGTERM (--drain_seconds, default 10 s): give `docker stop`
# a longer timeout (docker stop -t 30; compose: stop_grace_period).
STOPSIGNAL SIGTERM
# swarfd refuses a non-loopback address without authentication. Choose, by
# environment: tokens (FLAGS_auth_tokens_file=/run/secrets/swarf-tokens, a
# mounted file) or, where the network is the boundary (behind the balancer,
# on a private network), FLAGS_insecure_public=true.
ENTRYPOINT ["swarfd", "--listen=0.0.0.0:50051", "--data_dir=/var/lib/swarf", \
            "--tryfromenv=insecure_public,auth_tokens_file"]
CMD []
