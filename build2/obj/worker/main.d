build2/obj/worker/main.o: worker/main.c common/base/cli.h \
 common/base/log.h worker/worker.h
common/base/cli.h:
common/base/log.h:
worker/worker.h:
