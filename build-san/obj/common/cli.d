build-san/obj/common/cli.o: common/cli.c common/cli.h common/log.h
common/cli.h:
common/log.h:
